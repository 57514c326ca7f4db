"""Threat sources: key layout, the table by <source>/<id>, loaded zenoh configurations, events."""

from __future__ import annotations

import json
import time

import pytest

from companion.errors import ConfigError, ThreatPayloadError
from companion.security.deployment import init_deployment
from companion.threats.model import Threat, ThreatTable
from companion.threats.transport.bus import ThreatBus
from companion.threats.transport.update import ThreatUpdate, rejected_event
from tests.unit.flight.test_avoidance import Harness, run, trajectory_decision, until


@pytest.fixture(scope="module")
def deploy(tmp_path_factory):
    return init_deployment(
        tmp_path_factory.mktemp("deploy"),
        sources=["radar1", "radar2"],
        observers=["gcs"],
        listen=["tls/127.0.0.1:17447"],
        connect=["tls/127.0.0.1:17447"],
    )


def test_plain_bus_takes_both_layouts_with_the_source_from_the_key():
    bus = ThreatBus(1)
    assert bus.inbound.parse_key("uav/1/threats/t1") == ("local", "t1")
    assert bus.inbound.parse_key("uav/1/threats/radar1/t1") == ("radar1", "t1")
    for key in (
        "uav/1/threats/local/t1",
        "uav/1/threats/a/b/c",
        "uav/1/threats/bad source/t1",
        "uav/1/threats/radar1/bad id",
    ):
        with pytest.raises(ThreatPayloadError) as err:
            bus.inbound.parse_key(key)
        assert err.value.field == "key"


def test_the_companion_config_refuses_the_plain_layout(deploy):
    bus = ThreatBus(1, zenoh_config=deploy.configs["companion"])
    assert bus.require_source and bus.client.source is None and bus.security.identity == "companion"
    assert bus.listen == ("tls/127.0.0.1:17447",) and bus.connect == ()
    assert bus.inbound.parse_key("uav/1/threats/radar1/t1") == ("radar1", "t1")
    with pytest.raises(ThreatPayloadError, match="authenticated sources only") as err:
        bus.inbound.parse_key("uav/1/threats/t1")
    assert err.value.field == "key"


def test_a_source_config_puts_under_its_certificate_name(deploy):
    bus = ThreatBus(1, zenoh_config=deploy.configs["radar1"])
    assert not bus.require_source and bus.client.source == "radar1"
    assert bus.client.threat_leaf("p1") == "threats/radar1/p1"
    assert (
        ThreatBus(1, zenoh_config=deploy.configs["radar1"], source="radar2").client.threat_leaf("p1")
        == "threats/radar2/p1"
    )
    assert ThreatBus(1).client.threat_leaf("p1") == "threats/p1"
    assert ThreatBus(1, source="radar9").client.threat_leaf("p1") == "threats/radar9/p1"
    overridden = ThreatBus(1, zenoh_config=deploy.configs["radar1"], connect=["tls/127.0.0.1:1"])
    assert overridden.connect == ("tls/127.0.0.1:1",)


def test_a_bad_config_file_is_named(tmp_path, deploy):
    with pytest.raises(ConfigError, match=f"{tmp_path / 'nope.json5'}: no such file"):
        ThreatBus(1, zenoh_config=tmp_path / "nope.json5")
    bad = tmp_path / "bad.json5"
    bad.write_text('{mode: "peer", access_control: {enabled: 3}}')
    with pytest.raises(ConfigError, match="bad.json5: not a valid zenoh configuration"):
        ThreatBus(1, zenoh_config=bad)
    cfg = json.loads(deploy.configs["radar1"].read_text().split("\n", 1)[1])
    cfg["transport"]["link"]["tls"]["connect_certificate"] = str(tmp_path / "gone.pem")
    missing = tmp_path / "missing-cert.json5"
    missing.write_text(json.dumps(cfg))
    with pytest.raises(ConfigError, match="connect_certificate: no such file .*gone.pem"):
        ThreatBus(1, zenoh_config=missing)


def test_zenoh_settings_take_a_config_path(deploy):
    from companion.config import load_settings

    settings = load_settings(None, {"zenoh": {"config": str(deploy.configs["companion"])}})
    bus = ThreatBus.from_settings(settings.zenoh)
    assert bus.require_source and bus.security.path == str(deploy.configs["companion"])
    with pytest.raises(ConfigError, match="zenoh.config"):
        load_settings(None, {"zenoh": {"config": ""}})


def test_two_sources_with_the_same_id_do_not_touch_each_other():
    table = ThreatTable()
    a = Threat("t1", "popup", "local_ned", (1.0, 0.0, 0.0), source="radar1")
    b = Threat("t1", "popup", "local_ned", (2.0, 0.0, 0.0), source="radar2")
    c = Threat("t1", "popup", "local_ned", (3.0, 0.0, 0.0))
    assert not table.put(a) and not table.put(b) and not table.put(c)
    assert [t.uid for t in table.snapshot()] == ["radar1/t1", "radar2/t1", "t1"]
    assert table.delete("radar2/t1") and not table.delete("radar2/t1")
    assert table.get("radar1/t1").position == (1.0, 0.0, 0.0) and table.get("t1").source == "local"


def test_rejected_event_names_the_source():
    err = ThreatPayloadError("radius_m: must be > 0")
    err.field = "radius_m"
    update = ThreatUpdate("rejected", "p1", None, err, "uav/1/threats/radar1/p1", 1.0, 0.0, 1, "radar1")
    event = rejected_event(update)
    assert event["source"] == "radar1" and event["threat_id"] == "radar1/p1" and event["field"] == "radius_m"


def test_the_decision_event_names_the_source_of_its_threat():
    h = Harness(monitor_period_s=60.0)
    h.manager.on_threats_script = [trajectory_decision("replan", threat_id="radar1/p1")]

    async def main(h):
        await h.start()
        threat = Threat("p1", "popup", "local_ned", (8.0, 0.0, -10.0), radius_m=3.0, received_t_s=5.0, source="radar1")
        h.bus.handler(
            ThreatUpdate("put", "p1", threat, None, "uav/1/threats/radar1/p1", 5.0, time.monotonic(), 1, "radar1")
        )
        await until(lambda: h.bus.events, "the event")
        event = h.bus.events[0]
        assert event["threat_id"] == "radar1/p1" and event["source"] == "radar1"
        assert h.texts[0][0].startswith("AVOID radar1/p1: replan")
        threat_lines = [f for kind, f in h.records if kind == "threat"]
        assert threat_lines[0]["id"] == "radar1/p1" and threat_lines[0]["source"] == "radar1"
        h.bus.handler(
            ThreatUpdate("delete", "p1", None, None, "uav/1/threats/radar2/p1", 6.0, time.monotonic(), 2, "radar2")
        )
        await until(lambda: len([r for r in h.records if r[0] == "threat"]) == 2, "the delete")
        assert "radar1/p1" in h.reactor.table  # radar2 cannot delete radar1's p1

    run(main, h)
