"""The threats held, kept across a companion crash (issue 11; ``companion.threats.snapshot``).

``open_snapshots`` writes the snapshot from now on when ``state.dir`` is set (at every change of
the reactor's table); ``restore_threats`` puts a resumed flight's live threats back.
"""

from __future__ import annotations

import logging

from companion.threats.snapshot import SnapshotWriter, load_live_threats, snapshot_path

__all__ = ["open_snapshots", "restore_threats"]

log = logging.getLogger(__name__)


def open_snapshots(settings, reactor, home_lla) -> SnapshotWriter | None:
    """The snapshot writer of ``reactor``'s table (None without ``state.dir``)."""
    if not settings.state.dir:
        return None
    path = snapshot_path(settings.state.dir, settings.zenoh.sysid)
    writer = SnapshotWriter(path, sysid=settings.zenoh.sysid, home_lla=home_lla)
    reactor.on_table_change = writer.save
    return writer


def restore_threats(daemon) -> None:
    """A resume: put the live threats of the snapshot back in the table (none when there is no
    usable snapshot: that is logged, never fatal), then write the snapshot afresh."""
    s, reactor, now = daemon.settings, daemon.threats, daemon.clock.now_s
    if reactor is None:
        return
    if not s.state.dir:
        log.warning("resuming without a state directory (--state-dir): no threats are restored")
        return
    path = snapshot_path(s.state.dir, s.zenoh.sysid)
    threats = load_live_threats(path, now(), sysid=s.zenoh.sysid, home_lla=daemon.home_lla)
    ids = reactor.restore(threats)
    daemon.summary.threats_restored = len(ids)
    daemon.sink.event(
        "threats_restored",
        ids=ids,
        snapshot=str(path),
        remaining_ttl_s={t.id: round(t.expires_t_s - now(), 2) for t in threats if t.ttl_s is not None},
    )
