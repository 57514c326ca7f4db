"""The companion's state on disk: the threat snapshot that survives a crash (issue 11).

``companion run`` with a state directory (``[state] dir`` or ``--state-dir``) writes the threats
it holds to ``<dir>/threats-uav<sysid>.json`` every time the table changes (a PUT, a DELETE, an
ADS-B report), so that ``companion run --resume`` after a crash knows them again. The file is
written atomically (a temporary file in the same directory, flushed and fsynced, then
``os.replace``): a reader sees the previous snapshot or the new one, never half of one.

Times are mission times, i.e. the *vehicle's* seconds since boot (``companion.flight.reference.
VehicleClock``): they keep running while the companion is dead, so each threat is stored with
its position at ``received_t_s`` and its absolute expiry ``expires_t_s`` (null: until deleted),
and a resumed companion keeps the remaining TTL and predicts a moving threat from where it was
seen. Positions are local NED about home (``home_lla`` is stored with them).

Reading is forgiving by design: a snapshot that is missing, unreadable or from another flight
(the vehicle's clock went back, i.e. it rebooted; another home; another system id) gives no
threats and a log line, never an error that stops a resume (``load_live_threats``).

Pure functions (``snapshot_to_dict``, ``snapshot_from_dict``, ``live_threats``) do the work;
``write_snapshot`` / ``read_snapshot`` are the file I/O; ``SnapshotWriter`` moves the writes off
the event loop, in order.
"""

from __future__ import annotations

import json
import logging
import math
import os
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.errors import CompanionError
from companion.geo import LocalFrame
from companion.threats.model import TRAFFIC, Threat

__all__ = [
    "SNAPSHOT_VERSION",
    "SnapshotError",
    "ThreatSnapshot",
    "snapshot_path",
    "snapshot_to_dict",
    "snapshot_from_dict",
    "write_snapshot",
    "read_snapshot",
    "live_threats",
    "load_live_threats",
    "SnapshotWriter",
]

log = logging.getLogger(__name__)

SNAPSHOT_VERSION = 1
#: The vehicle's clock may read this much (s) below the snapshot's time without a reboot
#: (the companion's clock estimate is extrapolated between messages).
CLOCK_TOLERANCE_S = 1.0
#: Homes further apart than this (m) are another flight's: the snapshot is not used.
HOME_TOLERANCE_M = 1.0


class SnapshotError(CompanionError):
    """A snapshot file cannot be read or is not a threat snapshot (the message says why)."""


@dataclass(frozen=True)
class ThreatSnapshot:
    """The threats one companion held at one time.

    Attributes
    ----------
    sysid : int
        The vehicle (key prefix ``uav/<sysid>``).
    written_t_s : float
        Mission time of the snapshot (the vehicle's seconds since boot).
    written_unix_s : float
        Wall-clock time of the snapshot (for people; not used to expire threats).
    home_lla : tuple of 3 float or None
        The home the positions refer to.
    threats : tuple of Threat
        Local NED threats, each with ``received_t_s`` and ``ttl_s`` on the mission clock.
    """

    sysid: int
    written_t_s: float
    written_unix_s: float
    home_lla: tuple | None
    threats: tuple[Threat, ...]


def snapshot_path(state_dir, sysid: int) -> Path:
    """``<state_dir>/threats-uav<sysid>.json``."""
    return Path(state_dir) / f"threats-uav{int(sysid)}.json"


def _threat_to_dict(threat: Threat) -> dict:
    expires = threat.expires_t_s
    return {
        "id": threat.id,
        "kind": threat.kind,
        "frame": threat.frame,
        "position": [float(v) for v in threat.position],
        "velocity_ned_m_s": [float(v) for v in threat.velocity_ned_m_s],
        "radius_m": float(threat.radius_m),
        "received_t_s": float(threat.received_t_s),
        "expires_t_s": float(expires) if math.isfinite(expires) else None,
        "traffic": threat.traffic,
    }


def snapshot_to_dict(snapshot: ThreatSnapshot) -> dict:
    """The JSON document of ``snapshot`` (version, times, home, threats)."""
    return {
        "version": SNAPSHOT_VERSION,
        "sysid": snapshot.sysid,
        "written_t_s": float(snapshot.written_t_s),
        "written_unix_s": float(snapshot.written_unix_s),
        "home_lla": None if snapshot.home_lla is None else [float(v) for v in snapshot.home_lla],
        "threats": [_threat_to_dict(t) for t in snapshot.threats],
    }


def _number(data: dict, key: str, where: str, optional: bool = False) -> float | None:
    value = data.get(key)
    if value is None and optional:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SnapshotError(f"{where}{key}: expected a finite number, got {value!r}")
    return float(value)


def _vector(data: dict, key: str, where: str) -> tuple:
    value = data.get(key)
    if (
        not isinstance(value, list)
        or len(value) != 3
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    ):
        raise SnapshotError(f"{where}{key}: expected 3 finite numbers, got {value!r}")
    return tuple(float(v) for v in value)


def _threat_from_dict(data, index: int) -> Threat:
    where = f"threats[{index}]."
    if not isinstance(data, dict):
        raise SnapshotError(f"threats[{index}]: expected an object, got {type(data).__name__}")
    if data.get("frame") != "local_ned":
        raise SnapshotError(f"{where}frame: expected 'local_ned', got {data.get('frame')!r}")
    received = _number(data, "received_t_s", where)
    expires = _number(data, "expires_t_s", where, optional=True)
    radius = _number(data, "radius_m", where)
    traffic = data.get("traffic", "drone")
    if traffic not in TRAFFIC:
        raise SnapshotError(f"{where}traffic: expected one of {', '.join(TRAFFIC)}, got {traffic!r}")
    try:
        return Threat(
            str(data["id"]),
            str(data["kind"]),
            "local_ned",
            _vector(data, "position", where),
            _vector(data, "velocity_ned_m_s", where),
            radius,
            None if expires is None else expires - received,
            received,
            traffic=traffic,
        )
    except KeyError as exc:
        raise SnapshotError(f"{where}{exc.args[0]}: missing") from None


def snapshot_from_dict(data) -> ThreatSnapshot:
    """Parse a snapshot document.

    Raises
    ------
    SnapshotError
        Naming the first field that is missing or wrong.
    """
    if not isinstance(data, dict):
        raise SnapshotError(f"expected a JSON object, got {type(data).__name__}")
    if data.get("version") != SNAPSHOT_VERSION:
        raise SnapshotError(f"version: expected {SNAPSHOT_VERSION}, got {data.get('version')!r}")
    sysid = data.get("sysid")
    if isinstance(sysid, bool) or not isinstance(sysid, int):
        raise SnapshotError(f"sysid: expected an integer, got {sysid!r}")
    home = data.get("home_lla")
    home_lla = None if home is None else _vector(data, "home_lla", "")
    threats = data.get("threats")
    if not isinstance(threats, list):
        raise SnapshotError(f"threats: expected a list, got {type(threats).__name__}")
    return ThreatSnapshot(
        sysid,
        _number(data, "written_t_s", ""),
        _number(data, "written_unix_s", ""),
        home_lla,
        tuple(_threat_from_dict(t, i) for i, t in enumerate(threats)),
    )


def write_snapshot(path, snapshot: ThreatSnapshot) -> None:
    """Write ``snapshot`` to ``path`` atomically (temporary file, fsync, ``os.replace``).

    Creates the directory. Raises ``OSError`` when it cannot be written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(snapshot_to_dict(snapshot), separators=(",", ":"), allow_nan=False)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def read_snapshot(path) -> ThreatSnapshot | None:
    """Read the snapshot at ``path``; None when there is none.

    Raises
    ------
    SnapshotError
        The file cannot be read, is not JSON or is not a snapshot (the message names the file).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as exc:
        raise SnapshotError(f"threat snapshot {path}: cannot be read: {exc}") from None
    try:
        return snapshot_from_dict(json.loads(text))
    except json.JSONDecodeError as exc:
        raise SnapshotError(f"threat snapshot {path}: not JSON: {exc}") from None
    except SnapshotError as exc:
        raise SnapshotError(f"threat snapshot {path}: {exc}") from None


def live_threats(
    snapshot: ThreatSnapshot,
    now_t_s: float,
    *,
    sysid: int,
    home_lla=None,
    clock_tolerance_s: float = CLOCK_TOLERANCE_S,
    home_tolerance_m: float = HOME_TOLERANCE_M,
) -> tuple[list[Threat], str]:
    """The threats of ``snapshot`` still alive at mission time ``now_t_s``.

    Parameters
    ----------
    snapshot : ThreatSnapshot
    now_t_s : float
        Mission time now (the vehicle's clock).
    sysid : int
        The vehicle flown: another vehicle's snapshot gives nothing.
    home_lla : tuple, optional
        The current home: a snapshot about another home (further than ``home_tolerance_m``)
        gives nothing.

    Returns
    -------
    (list of Threat, str)
        The live threats (expiry and ``received_t_s`` unchanged, so the remaining TTL is kept),
        and a note on what was dropped and why (empty when nothing was).
    """
    if snapshot.sysid != sysid:
        return [], f"written for system {snapshot.sysid}, not {sysid}"
    if now_t_s < snapshot.written_t_s - clock_tolerance_s:
        return [], (
            f"the vehicle's clock ({now_t_s:.1f} s) is before the snapshot's "
            f"({snapshot.written_t_s:.1f} s): the vehicle rebooted"
        )
    if home_lla is not None and snapshot.home_lla is not None:
        moved = float(np.linalg.norm(LocalFrame(*home_lla).to_ned(*snapshot.home_lla)))
        if moved > home_tolerance_m:
            return [], f"written about another home ({moved:.1f} m away)"
    live = [t for t in snapshot.threats if t.expires_t_s > now_t_s]
    expired = len(snapshot.threats) - len(live)
    return live, f"{expired} expired" if expired else ""


def load_live_threats(path, now_t_s: float, *, sysid: int, home_lla=None) -> list[Threat]:
    """The live threats of the snapshot at ``path``; never raises for a bad or missing file.

    A snapshot that cannot be used is logged (error for a corrupt file, warning for another
    flight's) and gives no threats: a broken snapshot must never stop a resume.
    """
    try:
        snapshot = read_snapshot(path)
    except SnapshotError as exc:
        log.error("%s; resuming without the threats it held", exc)
        return []
    if snapshot is None:
        log.warning("no threat snapshot at %s: resuming without threats", path)
        return []
    threats, note = live_threats(snapshot, now_t_s, sysid=sysid, home_lla=home_lla)
    if note:
        log.warning("threat snapshot %s: %s", path, note)
    log.info("threat snapshot %s: %d live threats (%s)", path, len(threats), ", ".join(t.id for t in threats) or "none")
    return threats


class SnapshotWriter:
    """Writes snapshots in a background thread, in the order given (the newest wins).

    Parameters
    ----------
    path : path
        The snapshot file (``snapshot_path``).
    sysid : int
    home_lla : tuple
    """

    def __init__(self, path, *, sysid: int, home_lla) -> None:
        self.path = Path(path)
        self.sysid = int(sysid)
        self.home_lla = tuple(home_lla) if home_lla is not None else None
        self.writes = 0
        self.failures = 0
        self._executor = ThreadPoolExecutor(1, thread_name_prefix="state")

    def save(self, threats, now_t_s: float) -> None:
        """Queue a snapshot of ``threats`` (expired ones are left out) at mission time ``now_t_s``."""
        live = tuple(t for t in threats if t.expires_t_s > now_t_s)
        snap = ThreatSnapshot(self.sysid, float(now_t_s), time.time(), self.home_lla, live)
        self._executor.submit(self._write, snap)

    def _write(self, snap: ThreatSnapshot) -> None:
        try:
            write_snapshot(self.path, snap)
            self.writes += 1
        except (OSError, ValueError) as exc:  # a full disk must not stop the flight
            self.failures += 1
            log.error("threat snapshot %s not written: %s", self.path, exc)

    def close(self) -> None:
        """Finish the queued writes."""
        self._executor.shutdown(wait=True)
