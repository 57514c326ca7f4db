"""The threat snapshot (companion.threats.snapshot): written atomically, read back with the TTL kept,
forgiving of a bad file (issue 11)."""

from __future__ import annotations

import json
import logging
import math

import pytest

from companion.geo import LocalFrame
from companion.threats.model import Threat
from companion.threats.snapshot import (
    SnapshotError,
    SnapshotWriter,
    ThreatSnapshot,
    live_threats,
    load_live_threats,
    read_snapshot,
    snapshot_from_dict,
    snapshot_path,
    snapshot_to_dict,
    write_snapshot,
)

HOME = (47.3977, 8.5456, 488.0)
POPUP = Threat("p1", "popup", "local_ned", (10.0, 20.0, -15.0), (0.0, 0.0, 0.0), 4.0, 50.0, 100.0)
MOVER = Threat("m1", "moving", "local_ned", (0.0, 0.0, -15.0), (1.0, -2.0, 0.0), 3.0, None, 110.0)


def snapshot(*threats, written_t_s=120.0, sysid=1, home=HOME) -> ThreatSnapshot:
    return ThreatSnapshot(sysid, written_t_s, 1.7e9, home, tuple(threats))


def test_a_written_snapshot_reads_back_the_same_threats(tmp_path):
    path = snapshot_path(tmp_path / "state", 1)
    write_snapshot(path, snapshot(POPUP, MOVER))
    back = read_snapshot(path)
    assert back.threats == (POPUP, MOVER)
    assert back.written_t_s == 120.0 and back.home_lla == HOME and back.sysid == 1
    assert [p.name for p in path.parent.iterdir()] == ["threats-uav1.json"], "no temporary file left"


def test_the_file_holds_each_threats_absolute_expiry():
    doc = snapshot_to_dict(snapshot(POPUP, MOVER))
    assert doc["threats"][0]["expires_t_s"] == 150.0 and doc["threats"][1]["expires_t_s"] is None
    assert snapshot_from_dict(json.loads(json.dumps(doc))).threats[0].ttl_s == 50.0


def test_the_remaining_ttl_is_kept_and_expired_threats_dropped():
    threats, note = live_threats(snapshot(POPUP, MOVER), 130.0, sysid=1)
    assert threats == [POPUP, MOVER]
    assert threats[0].expires_t_s - 130.0 == pytest.approx(20.0)  # 50 s ttl put at 100 s
    assert threats[1].position_at(130.0) == pytest.approx([20.0, -40.0, -15.0])
    later, note = live_threats(snapshot(POPUP, MOVER), 150.0, sysid=1)
    assert later == [MOVER] and note == "1 expired"


@pytest.mark.parametrize(
    "kwargs, now, why",
    [
        ({"sysid": 2}, 130.0, "system 1, not 2"),
        ({"sysid": 1}, 50.0, "rebooted"),
        ({"sysid": 1, "home_lla": LocalFrame(*HOME).to_lla(30.0, 0.0, 0.0)}, 130.0, "another home"),
    ],
)
def test_another_flights_snapshot_gives_nothing(kwargs, now, why):
    threats, note = live_threats(snapshot(POPUP), now, **kwargs)
    assert threats == [] and why in note


def test_the_same_home_within_a_metre_is_accepted():
    near = tuple(float(v) for v in LocalFrame(*HOME).to_lla(0.3, 0.2, 0.0))
    assert live_threats(snapshot(POPUP), 130.0, sysid=1, home_lla=near)[0] == [POPUP]


@pytest.mark.parametrize(
    "text, field",
    [
        ("{not json", "not JSON"),
        ('{"version": 9}', "version"),
        (
            '{"version": 1, "sysid": 1, "written_t_s": 1, "written_unix_s": 1, "home_lla": null, "threats": {}}',
            "threats: expected a list",
        ),
        (
            '{"version": 1, "sysid": 1, "written_t_s": 1, "written_unix_s": 1, "home_lla": null, "threats": '
            '[{"id": "a", "kind": "popup", "frame": "local_ned", "position": [1, 2], "velocity_ned_m_s": [0, 0, 0],'
            ' "radius_m": 1, "received_t_s": 0, "expires_t_s": null}]}',
            "threats[0].position",
        ),
        ("[]", "expected a JSON object"),
    ],
)
def test_a_corrupt_file_is_a_clear_error(tmp_path, text, field):
    path = tmp_path / "threats-uav1.json"
    path.write_text(text)
    with pytest.raises(SnapshotError) as err:
        read_snapshot(path)
    assert field in str(err.value) and str(path) in str(err.value)


def test_a_corrupt_or_missing_snapshot_never_stops_a_resume(tmp_path, caplog):
    path = tmp_path / "threats-uav1.json"
    assert load_live_threats(path, 130.0, sysid=1) == []
    path.write_bytes(b"\x00\xff truncated")
    with caplog.at_level(logging.ERROR, logger="companion.threats.snapshot"):
        assert load_live_threats(path, 130.0, sysid=1) == []
    assert "resuming without the threats" in caplog.text


def test_the_writer_writes_in_order_and_leaves_expired_threats_out(tmp_path):
    path = snapshot_path(tmp_path, 3)
    writer = SnapshotWriter(path, sysid=3, home_lla=HOME)
    writer.save([POPUP, MOVER], 120.0)
    writer.save([POPUP, MOVER], 160.0)  # the popup expired at 150 s
    writer.close()
    back = read_snapshot(path)
    assert writer.writes == 2 and back.written_t_s == 160.0 and back.threats == (MOVER,)
    assert back.sysid == 3 and math.isinf(back.threats[0].expires_t_s)


def test_a_write_that_fails_is_logged_not_raised(tmp_path, caplog):
    blocker = tmp_path / "file"
    blocker.write_text("")
    writer = SnapshotWriter(blocker / "sub" / "threats-uav1.json", sysid=1, home_lla=HOME)
    with caplog.at_level(logging.ERROR, logger="companion.threats.snapshot"):
        writer.save([POPUP], 120.0)
        writer.close()
    assert writer.failures == 1 and "not written" in caplog.text
