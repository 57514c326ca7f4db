"""Threats over real zenoh between separate processes (DESIGN section 6).

The test process holds the companion side (a ``ThreatBus`` listening on a free TCP port);
``companion threat ...`` runs as a separate process and connects to it, directly or through a
zenoh router running in a third process.
"""

from __future__ import annotations

import asyncio
import socket
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from companion.sitl.processes import spawn
from companion.threats.model import ThreatTable
from companion.threats.transport.bus import ThreatBus
from heli_common.ports import free_port
from tests.support import REPO_ROOT

pytestmark = pytest.mark.integration

COMPANION = [sys.executable, "-m", "companion.cli"]


def companion(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([*COMPANION, *args], capture_output=True, text=True, timeout=timeout, cwd=REPO_ROOT)


def wait_for(predicate, timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


@pytest.fixture
def listener():
    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    bus = ThreatBus(7, listen=[endpoint]).open()
    updates: list = []
    bus.inbound.subscribe(updates.append)
    table = ThreatTable()
    bus.outbound.serve_threats(table.snapshot)
    yield endpoint, bus, updates, table
    bus.close()


def test_add_remove_and_list_between_processes(listener):
    endpoint, bus, updates, table = listener
    res = companion(
        "threat",
        "add",
        "--id",
        "m1",
        "--pos",
        "44,30,-20",
        "--vel",
        "-1,1,0",
        "--radius",
        "3",
        "--ttl",
        "60",
        "--sysid",
        "7",
        "--zenoh-connect",
        endpoint,
    )
    assert res.returncode == 0, res.stderr
    assert wait_for(lambda: len(updates) >= 1)
    put = updates[0]
    assert put.action == "put" and put.threat_id == "m1" and put.error is None
    assert put.threat.kind == "moving" and put.threat.position == (44.0, 30.0, -20.0)
    assert put.threat.velocity_ned_m_s == (-1.0, 1.0, 0.0) and put.threat.ttl_s == 60.0
    table.put(put.threat)

    res = companion("threat", "list", "--sysid", "7", "--zenoh-connect", endpoint)
    assert res.returncode == 0, res.stderr
    assert "m1: moving r=3.0 m" in res.stdout

    res = companion("threat", "move", "--id", "m1", "--vel", "0,2,0", "--sysid", "7", "--zenoh-connect", endpoint)
    assert res.returncode == 0, res.stderr
    assert wait_for(lambda: len(updates) >= 2)
    moved = updates[1].threat
    assert moved.velocity_ned_m_s == (0.0, 2.0, 0.0) and moved.radius_m == 3.0

    res = companion("threat", "remove", "--id", "m1", "--sysid", "7", "--zenoh-connect", endpoint)
    assert res.returncode == 0, res.stderr
    assert wait_for(lambda: len(updates) >= 3)
    assert updates[2].action == "delete" and updates[2].threat_id == "m1"
    assert bus.stats()["received"] == 3 and bus.stats()["rejected"] == 0


def test_invalid_payload_from_another_process_is_rejected_naming_the_field(listener):
    endpoint, bus, updates, _ = listener
    script = textwrap.dedent(f"""
        from companion.threats.transport.bus import ThreatBus
        with ThreatBus(7, listen=[], connect=["{endpoint}"]) as bus:
            bus.client.wait_for_subscriber(10.0, "bad")
            bus.client.put_raw("bad", b'{{"v": 1, "id": "bad", "kind": "popup", "frame": "local_ned", '
                               b'"position": [1, 2, 3], "radius_m": -4}}')
            bus.client.put_raw("junk", b"not json")
            bus.client.put_raw("other", b'{{"v": 1, "id": "t1", "kind": "popup", "frame": "local_ned", '
                                 b'"position": [1, 2, 3], "radius_m": 4}}')
    """)
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60, cwd=REPO_ROOT)
    assert res.returncode == 0, res.stderr
    assert wait_for(lambda: len(updates) >= 3)
    fields = [(u.action, u.threat_id, getattr(u.error, "field", None)) for u in updates]
    assert fields == [("rejected", "bad", "radius_m"), ("rejected", "junk", "payload"), ("rejected", "other", "id")]


def test_play_scenario_delivers_every_event_in_order(listener, tmp_path):
    endpoint, _, updates, _ = listener
    scenario = tmp_path / "s.toml"
    scenario.write_text(
        textwrap.dedent("""
        [[event]]
        at_s = 0.5
        action = "add"
        id = "p1"
        pos = [75.0, 75.0, -20.0]
        radius_m = 5.0
        [[event]]
        at_s = 1.0
        action = "move"
        id = "p1"
        vel = [1.0, 0.0, 0.0]
        [[event]]
        at_s = 2.0
        action = "remove"
        id = "p1"
    """)
    )
    res = companion("threat", "play", str(scenario), "--time-scale", "4", "--sysid", "7", "--zenoh-connect", endpoint)
    assert res.returncode == 0, res.stderr
    assert wait_for(lambda: len(updates) >= 3)
    assert [u.action for u in updates] == ["put", "put", "delete"]
    assert updates[1].threat.kind == "moving" and updates[1].threat.velocity_ned_m_s == (1.0, 0.0, 0.0)


def test_through_a_router_and_into_an_asyncio_loop(tmp_path):
    router_ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    script = textwrap.dedent(f"""
        import signal
        from companion.threats.transport.bus import ThreatBus
        bus = ThreatBus(3, listen=["{router_ep}"], mode="router").open()
        print("ready", flush=True)
        try:
            signal.pause()                     # until stopped (SIGINT)
        except KeyboardInterrupt:
            pass
        bus.close()
    """)
    router = spawn([sys.executable, "-c", script], tmp_path / "router.log", cwd=REPO_ROOT)
    try:
        router.wait_ready(router.log_contains("ready"), 60.0, "'ready'")

        async def main():
            loop = asyncio.get_running_loop()
            got: list = []
            arrived = asyncio.Event()

            def on_update(update):
                got.append((update, threading.get_ident()))
                arrived.set()

            bus = ThreatBus(3, listen=[], connect=[router_ep], mode="client").open()
            try:
                bus.inbound.subscribe(on_update, loop=loop)
                res = await asyncio.to_thread(
                    companion,
                    "threat",
                    "add",
                    "--id",
                    "r1",
                    "--pos",
                    "1,2,-3",
                    "--radius",
                    "2",
                    "--sysid",
                    "3",
                    "--zenoh-connect",
                    router_ep,
                )
                assert res.returncode == 0, res.stderr
                await asyncio.wait_for(arrived.wait(), 10.0)
            finally:
                bus.close()
            return got

        got = asyncio.run(main())
        update, thread_id = got[0]
        assert update.action == "put" and update.threat.position == (1.0, 2.0, -3.0)
        assert thread_id == threading.get_ident()  # the handler ran on the loop's thread
    finally:
        router.stop()


def test_cli_without_a_listener_warns_and_fails():
    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    res = companion("threat", "remove", "--id", "x", "--zenoh-listen", endpoint, "--wait", "0.3")
    assert res.returncode == 1
    assert "no subscriber" in res.stderr and "Traceback" not in res.stderr
