"""FlightView: the record's lines as Foxglove channels, to MCAP and live (issue 14, items 1, 2)."""

import asyncio

import numpy as np
import pytest
from mcap.reader import make_reader

from companion.errors import CompanionError
from companion.record.flight_record import FlightRecorder, load_record
from companion.view import channels as ch
from companion.view.mcap_record import load_flight
from companion.view.publisher import FlightView
from companion.view.sinks import open_record_sinks, parse_foxglove_address
from tests.foxglove_client import collect

HOME = [47.397742, 8.545594, 488.0]


def flight_lines(samples: int = 60):
    """A small flight's record lines: header, world, plans, samples, a threat, decisions."""
    yield (
        "header",
        {
            "settings": {"seed": 0},
            "seed": 0,
            "home_lla": HOME,
            "mission": "m.plan",
            "waypoints_ned_m": [[0, 0, -15], [40, 0, -15]],
        },
    )
    yield (
        "world",
        {
            "world": {"bounds_min": [-50, -50, -60], "bounds_max": [80, 80, 0], "margin_m": 3.0},
            "obstacles": [
                {"type": "prism", "vertices": [[30, 22], [50, 22], [50, 38]]},
                {"type": "cylinder", "center": [12, 60], "radius": 8.0, "down_min": -40.0},
                {"type": "sphere", "center": [5, 5, -20], "radius": 2.0},
                {"type": "box", "min": [0, 0, -10], "max": [2, 3, 0]},
            ],
        },
    )
    yield (
        "plan",
        {
            "leg": 0,
            "seq": 2,
            "path_id": "leg0",
            "path_ned_m": [[0, 0, -15], [40, 0, -15]],
            "reference_ne": [[0, 0], [40, 0]],
            "tree": None,
            "summary": {},
        },
    )
    yield "alternatives", {"leg": 0, "t_s": 1.0, "paths": [[[0, 0, -15], [20, 5, -15], [40, 0, -15]]]}
    for k in range(samples):
        t = 1.0 + 0.1 * k
        if k == samples // 3:
            yield (
                "threat",
                {
                    "id": "mover1",
                    "source": "radar1",
                    "kind": "moving",
                    "position_ned_m": [30, 20, -15],
                    "velocity_ned_m_s": [0, -3, 0],
                    "radius_m": 3.0,
                    "t_s": t,
                },
            )
        if k == samples // 2:
            yield (
                "alert",
                {
                    "t_s": t,
                    "threat_id": "radar1/mover1",
                    "traffic": "drone",
                    "level": "low",
                    "action": 1,
                    "time_to_cpa_s": 2.5,
                    "horizontal_m": 1.2,
                    "vertical_m": 0.0,
                    "time_to_lowc_s": 1.5,
                    "text": "TRAFFIC radar1/mover1 LoWC in 2s, 1 m / 0 m",
                },
            )
            yield (
                "decision",
                {
                    "kind": "evade",
                    "reason": "mover1 in 2.0 s: evade",
                    "path_id": "evade-1",
                    "path_ned_m": [[20, 0, -15], [20, 5, -13]],
                    "t_s": t,
                    "leg": 0,
                },
            )
        yield (
            "sample",
            {
                "t_s": t,
                "ref_pos_ned_m": np.array([t, 0, -15]),
                "ref_vel_ned_m_s": [1, 0, 0],
                "pos_ned_m": [t - 0.05, 0.01, -15],
                "vel_ned_m_s": [1, 0, 0],
                "servo_us": [1500] * 4,
                "tracking_error_m": 0.05,
                "leg": 0,
                "path_id": "evade-1" if k >= samples // 2 else "leg0",
                "euler_rad": [0.0, -0.05, 0.0],
            },
        )
    yield "threat", {"id": "mover1", "removed": True, "known": True, "t_s": 9.0}
    yield "event", {"name": "landed", "t_s": 10.0}
    yield (
        "summary",
        {
            "legs_planned": 1,
            "legs_reached": 1,
            "landed": True,
            "rms_tracking_error_m": 0.05,
            "max_tracking_error_m": 0.05,
            "outcome": "completed",
        },
    )


def write_flight(sink, samples: int = 60) -> None:
    for line_type, fields in flight_lines(samples):
        sink.write(line_type, **fields)
    sink.close()


def test_the_mcap_has_every_channel_with_its_schema_and_monotonic_times(tmp_path):
    write_flight(FlightView(mcap_path=tmp_path / "f.mcap"))
    with open(tmp_path / "f.mcap", "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        topics = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        times: dict[str, list[int]] = {}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            times.setdefault(channel.topic, []).append(message.log_time)
    expected = (
        {topic for topic, _ in ch.RECORD_TOPICS.values()}
        | set(ch.SAMPLE_TOPICS)
        | {ch.SCENE_WORLD, ch.SCENE_PATHS, ch.SCENE_THREATS, ch.SCENE_VEHICLE, ch.TRANSFORMS, ch.LOCATION, ch.LOG}
    )
    assert set(topics) == expected
    assert topics[ch.SCENE_THREATS].name == "foxglove.SceneUpdate"
    assert topics[ch.LOCATION].name == "foxglove.LocationFix"
    assert topics["/flight/decision"].encoding == "jsonschema"
    assert all(schema.data for schema in topics.values())
    assert set(times) == expected  # every channel has messages
    for topic, stamps in times.items():
        assert stamps == sorted(stamps), topic


def test_the_mcap_reads_back_as_the_json_lines_record_does(tmp_path):
    write_flight(FlightView(mcap_path=tmp_path / "f.mcap"))
    write_flight(FlightRecorder(tmp_path / "f.jsonl"))
    mcap, jsonl = load_flight(tmp_path / "f.mcap"), load_record(tmp_path / "f.jsonl")
    assert (
        mcap.header,
        mcap.world,
        mcap.plans,
        mcap.decisions,
        mcap.threats,
        mcap.events,
        mcap.summary,
        mcap.alternatives,
        mcap.alerts,
    ) == (
        jsonl.header,
        jsonl.world,
        jsonl.plans,
        jsonl.decisions,
        jsonl.threats,
        jsonl.events,
        jsonl.summary,
        jsonl.alternatives,
        jsonl.alerts,
    )
    assert mcap.alerts and mcap.alerts[0]["threat_id"] == "radar1/mover1"
    assert set(mcap.samples) == set(jsonl.samples) and len(mcap.samples["t_s"]) == 60
    for key, column in jsonl.samples.items():
        np.testing.assert_allclose(mcap.samples[key], column)


def test_a_file_cut_short_gives_what_was_complete_and_junk_is_named(tmp_path):
    write_flight(FlightView(mcap_path=tmp_path / "f.mcap"), samples=3000)
    data = (tmp_path / "f.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    cut = load_flight(tmp_path / "cut.mcap")
    assert 0 < len(cut.samples["t_s"]) < 3000 and cut.summary is None and cut.header["home_lla"] == HOME
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file at all")
    with pytest.raises(CompanionError, match="junk.mcap: not a readable MCAP flight"):
        load_flight(tmp_path / "junk.mcap")
    with pytest.raises(CompanionError, match="no such flight record"):
        load_flight(tmp_path / "missing.mcap")


def test_a_live_client_sees_the_scene_the_threats_and_the_decisions():
    view = FlightView(server=("127.0.0.1", 0))

    async def fly_while_watching():
        watch = asyncio.create_task(
            collect(
                view.port,
                {"/flight/decision", ch.SCENE_THREATS, ch.SCENE_WORLD, ch.TRANSFORMS, "/vehicle/state"},
                seconds=3.0,
            )
        )
        await asyncio.sleep(0.5)  # the client subscribes first
        for line_type, fields in flight_lines():
            view.write(line_type, **fields)
            await asyncio.sleep(0.005)
        return await watch

    try:
        got = asyncio.run(fly_while_watching())
    finally:
        view.close()
    assert [m["kind"] for m in got.messages["/flight/decision"]] == ["evade"]
    assert got.messages["/flight/decision"][0]["reason"] == "mover1 in 2.0 s: evade"
    assert len(got.messages[ch.SCENE_THREATS]) >= 20  # the tube moves with every sample
    assert len(got.messages["/vehicle/state"]) == 60
    assert got.messages[ch.SCENE_WORLD] and got.messages[ch.TRANSFORMS]


def test_sinks_follow_the_record_suffix_and_the_address_is_checked(tmp_path):
    assert [type(s).__name__ for s in open_record_sinks(tmp_path / "a.jsonl").sinks] == ["FlightRecorder"]
    sinks = open_record_sinks(tmp_path / "a.mcap")
    assert [type(s).__name__ for s in sinks.sinks] == ["FlightView"]
    sinks.close()
    assert open_record_sinks(None).sinks == []
    assert parse_foxglove_address("8765") == ("127.0.0.1", 8765)
    assert parse_foxglove_address("0.0.0.0:0") == ("0.0.0.0", 0)
    for bad in ("", "host:", "host:99999", "eight"):
        with pytest.raises(Exception, match="--foxglove: expected"):
            parse_foxglove_address(bad)
