"""The live Foxglove view's load, for ``benchmarks/setpoint_jitter.py`` (issue 14).

``LiveViewLoad`` does what ``companion run --foxglove PORT`` adds to a flight: a Foxglove
WebSocket server (``companion.view``, foxglove-sdk, its threads at the normal policy, as the
daemon starts it), fed the flight record as the daemon feeds it (header, world
and plan once; a sample at ``link.record_rate_hz`` with the vehicle moving along the plan; a
threat and a decision at each replan), with a viewer connected and subscribed to every channel:
``tests/foxglove_client.py`` in another process, as Foxglove would be.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

from companion.config import LinkSettings  # noqa: E402
from companion.demo import DEMO_HOME  # noqa: E402
from companion.view.sinks import open_record_sinks  # noqa: E402
from companion.world.io import world_to_dict  # noqa: E402

CONNECT_S = 2.0  # the viewer's time to connect and subscribe before the stream starts


class LiveViewLoad:
    """A live server with a viewer subscribed for ``seconds`` (see the module docstring)."""

    def __init__(self, seconds: float) -> None:
        from benchmarks.worlds import make_world

        bench = make_world("2d", 0)
        self.path_ned_m = np.array([[*bench.start[:2], -10.0], [*bench.goal[:2], -10.0]])
        self.sinks = open_record_sinks(None, ("127.0.0.1", 0))
        self.port = next(sink.port for sink in self.sinks.sinks if getattr(sink, "port", None))
        self.sinks.write("header", home_lla=DEMO_HOME, seed=0)
        self.sinks.write("world", **world_to_dict(bench.world))
        self.sinks.write("plan", leg=0, seq=1, path_id="leg0", path_ned_m=self.path_ned_m)
        self.client = subprocess.Popen(
            [sys.executable, str(REPO / "tests" / "foxglove_client.py"), str(self.port), str(seconds + 2 * CONNECT_S)],
            stdout=subprocess.PIPE,
            text=True,
        )
        time.sleep(CONNECT_S)
        self.replans = 0

    async def feed(self, stop_at_s: float) -> None:
        """Samples at the record rate until ``stop_at_s`` (monotonic), as the daemon writes them."""
        period = 1.0 / LinkSettings().record_rate_hz
        t0 = time.monotonic()
        while (now := time.monotonic()) < stop_at_s:
            u = ((now - t0) / 30.0) % 1.0
            pos = (1 - u) * self.path_ned_m[0] + u * self.path_ned_m[1]
            self.sinks.write(
                "sample",
                t_s=now - t0,
                ref_pos_ned_m=pos,
                ref_vel_ned_m_s=[3.0, 3.0, 0.0],
                pos_ned_m=pos + 0.1,
                vel_ned_m_s=[3.0, 3.0, 0.0],
                servo_us=[1500, 1500, 1500, 1500],
                tracking_error_m=0.17,
                leg=0,
                path_id=f"replan-{self.replans}",
                euler_rad=[0.01, -0.02, 0.78],
            )
            await asyncio.sleep(period)

    def on_replan(self, path_ned_m=None) -> None:
        """A threat and the decision that answers it (as the threat reactor records them)."""
        self.replans += 1
        t_s = time.monotonic()
        self.sinks.write(
            "threat",
            id=f"t{self.replans}",
            source="bench",
            kind="moving",
            position_ned_m=[50.0, 50.0, -10.0],
            velocity_ned_m_s=[-2.0, 0.0, 0.0],
            radius_m=3.0,
            t_s=t_s,
        )
        self.sinks.write(
            "decision",
            kind="replan",
            reason="benchmark",
            path_id=f"replan-{self.replans}",
            path_ned_m=self.path_ned_m if path_ned_m is None else path_ned_m,
            t_s=t_s,
        )

    def close(self) -> dict:
        """Stop the server; the viewer's message counts per topic."""
        self.sinks.close()
        out, _ = self.client.communicate(timeout=30)
        lines = [line for line in out.splitlines() if line.startswith("{")]
        return json.loads(lines[-1]) if lines else {}
