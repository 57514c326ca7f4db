"""Authenticated threat sources over real zenoh sessions: mutual TLS and access control (issue 11).

The companion's session uses the configuration written by ``companion keys init`` (listening on
a free loopback ``tls/`` port); sources, observers and intruders are other sessions, in this
process or as ``companion threat`` processes. Every negative check is followed by a positive
control on the same companion session, so that "nothing arrived" is not a dead link.
"""

from __future__ import annotations

import json
import socket
import time

import pytest

from companion.security import keys
from companion.security.deployment import init_deployment
from companion.threats.model import Threat, ThreatTable
from companion.threats.transport import access, codec
from companion.threats.transport.bus import ThreatBus
from heli_common.ports import free_port
from tests.integration.test_threat_bus import companion, wait_for
from tests.unit.flight.test_avoidance import Harness, run, trajectory_decision, until

pytestmark = pytest.mark.integration

SETTLE_S = 1.0  # time for zenoh declarations to propagate between sessions


def popup(tid: str) -> bytes:
    return codec.encode(Threat(tid, "popup", "local_ned", (10.0, 0.0, -20.0), radius_m=3.0))


@pytest.fixture
def deploy(tmp_path):
    endpoint = f"tls/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    dep = init_deployment(
        tmp_path / "deploy", sources=["radar1", "radar2"], observers=["gcs"], listen=[endpoint], connect=[endpoint]
    )
    # an identity signed by the same CA but named in no rule
    ca = keys.load_identity(dep.ca_key, dep.ca_cert)
    intruder = keys.issue_identity(ca, "intruder")
    d = dep.directory
    keys.write_private_key(intruder, d / "intruder.key")
    keys.write_certificate(intruder, d / "intruder.pem")
    access.write_config(
        access.peer_config(ca_cert=dep.ca_cert, key=d / "intruder.key", cert=d / "intruder.pem", connect=[endpoint]),
        d / "intruder.json5",
    )
    dep.configs["intruder"] = d / "intruder.json5"
    # TLS that trusts the CA but presents no certificate
    nocert = {
        "mode": "peer",
        "scouting": {"multicast": {"enabled": False}},
        "listen": {"endpoints": []},
        "connect": {"endpoints": [endpoint]},
        "transport": {"link": {"tls": {"root_ca_certificate": str(dep.ca_cert)}}},
    }
    (d / "nocert.json5").write_text(json.dumps(nocert))
    dep.configs["nocert"] = d / "nocert.json5"
    dep.endpoint = endpoint
    return dep


@pytest.fixture
def secured(deploy):
    bus = ThreatBus(1, zenoh_config=deploy.configs["companion"]).open()
    updates: list = []
    bus.inbound.subscribe(updates.append)
    table = ThreatTable()
    bus.outbound.serve_threats(table.snapshot)
    yield deploy, bus, updates, table
    bus.close()


def peer(deploy, name: str, **kw) -> ThreatBus:
    return ThreatBus(1, zenoh_config=deploy.configs[name], **kw).open()


def test_an_authorised_source_adds_lists_and_removes_under_its_name(secured):
    dep, bus, updates, table = secured
    cfg = str(dep.configs["radar1"])
    res = companion("threat", "add", "--zenoh-config", cfg, "--id", "p1", "--pos", "10,0,-20", "--radius", "3")
    assert res.returncode == 0, res.stderr
    assert "PUT uav/1/threats/radar1/p1" in res.stdout
    assert wait_for(lambda: len(updates) >= 1)
    put = updates[0]
    assert (put.action, put.source, put.threat_id, put.uid) == ("put", "radar1", "p1", "radar1/p1")
    assert put.threat.source == "radar1" and put.threat.position == (10.0, 0.0, -20.0)
    table.put(put.threat)

    res = companion("threat", "list", "--zenoh-config", cfg)
    assert res.returncode == 0, res.stderr
    assert "radar1/p1: popup r=3.0 m" in res.stdout

    res = companion("threat", "remove", "--zenoh-config", cfg, "--id", "p1")
    assert res.returncode == 0, res.stderr
    assert wait_for(lambda: len(updates) >= 2)
    assert (updates[1].action, updates[1].uid) == ("delete", "radar1/p1")
    assert bus.stats()["rejected"] == 0


def test_an_unauthenticated_session_cannot_put(secured):
    dep, bus, updates, _ = secured
    host_port = dep.endpoint.split("/", 1)[1]
    sessions = [
        ThreatBus(1, listen=[], connect=[f"tcp/{host_port}"]).open(),  # plain TCP on the TLS port
        peer(dep, "nocert", source="radar1"),
    ]  # TLS without a certificate
    try:
        time.sleep(SETTLE_S)
        for s in sessions:
            assert s.connected_peers() == 0
            s.client.put_raw("radar1/x1", popup("x1"))
            s.client.put_raw("x2", popup("x2"))
        res = companion(
            "threat",
            "add",
            "--zenoh-connect",
            f"tcp/{host_port}",
            "--id",
            "x3",
            "--pos",
            "1,2,-3",
            "--radius",
            "2",
            "--wait",
            "1",
        )
        assert res.returncode == 1 and "no subscriber" in res.stderr
        with peer(dep, "radar1") as radar1:  # positive control
            assert radar1.client.wait_for_subscriber(10.0, "ok")
            radar1.client.put_raw("radar1/ok", popup("ok"))
            assert wait_for(lambda: updates)
        time.sleep(0.5)
        assert [u.uid for u in updates] == ["radar1/ok"]
    finally:
        for s in sessions:
            s.close()


def test_identities_of_the_ca_cannot_put_beyond_their_rights(secured):
    dep, bus, updates, _ = secured
    res = companion(
        "threat",
        "add",
        "--zenoh-config",
        str(dep.configs["gcs"]),
        "--id",
        "g1",
        "--pos",
        "1,2,-3",
        "--radius",
        "2",
        "--wait",
        "1",
    )
    assert res.returncode == 1 and "access control" in res.stderr  # no subscriber is visible to it
    with peer(dep, "gcs") as gcs, peer(dep, "intruder") as intruder, peer(dep, "radar2") as radar2:
        time.sleep(SETTLE_S)
        assert gcs.connected_peers() == 1 and intruder.connected_peers() == 1  # connected, yet refused
        for s in (gcs, intruder):
            for leaf in ("gcs/x", "intruder/x", "radar1/x", "x"):
                s.client.put_raw(leaf, popup("x"))
        radar2.client.put_raw("radar1/spoof", popup("spoof"))  # a source impersonating another
        radar2.client.put_raw("spoof", popup("spoof"))  # the unauthenticated layout
        radar2.session.delete("uav/1/threats/radar1/p1")
        radar2.client.put_raw("radar2/ok", popup("ok"))  # positive control
        assert wait_for(lambda: updates)
        time.sleep(0.5)
    assert [(u.action, u.uid) for u in updates] == [("put", "radar2/ok")]
    assert bus.stats()["received"] == 1


def test_the_decision_event_names_the_source_and_only_authorised_readers_see_it(deploy):
    h = Harness(monitor_period_s=60.0)
    h.reactor.bus = ThreatBus(1, zenoh_config=deploy.configs["companion"], clock=lambda: 5.0)
    h.manager.on_threats_script = [trajectory_decision("replan", threat_id="radar1/p1")]
    seen: dict = {"gcs": [], "intruder": [], "radar1": []}

    async def main(h):
        await h.start()
        readers = {name: peer(deploy, name) for name in seen}
        try:
            for name, s in readers.items():
                s.subscribe_json("events", lambda key, msg, name=name: seen[name].append(msg))
            time.sleep(SETTLE_S)
            readers["radar1"].client.put_threat(Threat("p1", "popup", "local_ned", (8.0, 0.0, -10.0), radius_m=3.0))
            readers["radar1"].client.put_raw(
                "radar1/bad",
                b'{"v": 1, "id": "bad", "kind": "popup", "frame": "local_ned", "position": [1, 2, 3], "radius_m": -4}',
            )
            await until(lambda: len(seen["gcs"]) >= 2 and len(seen["radar1"]) >= 2, "events at the readers", 15.0)
            time.sleep(0.5)
        finally:
            for s in readers.values():
                s.close()
        decision = next(e for e in seen["gcs"] if e["event"] == "replan")
        assert decision["source"] == "radar1" and decision["threat_id"] == "radar1/p1"
        rejected = next(e for e in seen["gcs"] if e["event"] == "rejected")
        assert rejected["source"] == "radar1" and rejected["field"] == "radius_m"
        assert seen["intruder"] == []
        assert h.reactor.table.get("radar1/p1").source == "radar1"

    run(main, h)


def test_companion_run_refuses_a_bad_zenoh_config_before_connecting(tmp_path, deploy):
    started = time.monotonic()
    res = companion("run", "--zenoh-config", str(tmp_path / "nope.json5"), "--connect", "udpin://127.0.0.1:9")
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert f"--zenoh-config {tmp_path / 'nope.json5'}: no such file" in res.stderr
    (deploy.directory / "companion.pem").unlink()
    res = companion("run", "--zenoh-config", str(deploy.configs["companion"]), "--connect", "udpin://127.0.0.1:9")
    assert res.returncode == 2 and "companion.pem" in res.stderr and "no such file" in res.stderr
    assert time.monotonic() - started < 30.0  # not after waiting for a vehicle


def test_companion_threat_with_a_bad_zenoh_config_is_one_line(tmp_path):
    res = companion(
        "threat",
        "add",
        "--zenoh-config",
        str(tmp_path / "nope.json5"),
        "--id",
        "p1",
        "--pos",
        "1,2,-3",
        "--radius",
        "2",
    )
    assert res.returncode == 2 and res.stderr.strip().count("\n") == 0
    assert "nope.json5: no such file" in res.stderr
