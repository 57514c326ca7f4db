"""Docs that cannot go stale: the Python snippets that need a vehicle or a zenoh subscriber run
as scripts against real processes (a ``sim-vehicle``, a ``ThreatBus`` on zenoh), their ports
replaced by free ones. Judged by what the vehicle and the subscriber saw, not by the script."""

from __future__ import annotations

import socket
import subprocess
import sys
import time

import pytest
from docs_blocks import NEEDS_VEHICLE, NEEDS_ZENOH, ROOT, python_snippets
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from support import MavlinkPeer, checkout_env, start_sim_vehicle

from companion.threats.transport.bus import ThreatBus
from heli_common.ports import free_port

pytestmark = pytest.mark.integration


def _snippet(marker: str) -> str:
    found = [code for _, code in python_snippets() if marker in code]
    assert len(found) == 1, f"expected one snippet with {marker!r}, found {len(found)}"
    return found[0]


def _run(code: str, tmp_path, timeout_s: float = 120.0) -> subprocess.CompletedProcess:
    script = tmp_path / "snippet.py"
    script.write_text(code)
    return subprocess.run(
        [sys.executable, str(script)], cwd=ROOT, env=checkout_env(), capture_output=True, text=True, timeout=timeout_s
    )


def test_the_mavsdk_snippet_arms_and_takes_off_a_real_vehicle(tmp_path):
    with start_sim_vehicle(speedup=2.0) as sim:
        out = _run(_snippet(NEEDS_VEHICLE).replace("14555", str(sim.port)), tmp_path)
        assert out.returncode == 0, out.stderr[-2000:]
        with MavlinkPeer(sim.port, sim.sysid) as gcs:
            beat = gcs.wait("HEARTBEAT", timeout_s=5.0, condition=lambda m: m.get_srcSystem() == sim.sysid)
            assert beat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED, "the vehicle is not armed"


def test_the_threat_bus_snippet_puts_a_threat_to_a_real_subscriber(tmp_path):
    port = free_port(socket.SOCK_STREAM)
    updates: list = []
    with ThreatBus(1, listen=[f"tcp/127.0.0.1:{port}"]) as bus:
        bus.inbound.subscribe(updates.append)
        out = _run(_snippet(NEEDS_ZENOH).replace("7448", str(port)), tmp_path)
        assert out.returncode == 0, out.stderr[-2000:]
        deadline = time.monotonic() + 10.0
        while not updates and time.monotonic() < deadline:
            time.sleep(0.05)
    assert updates and updates[0].action == "put" and updates[0].error is None
    assert updates[0].threat.id == "m1" and updates[0].threat.position == (44.0, 30.0, -20.0)
