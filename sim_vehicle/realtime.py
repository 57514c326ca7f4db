"""The real-time loop of ``sim-vehicle``: physics, MAVLink input, heartbeat, streams and housekeeping at their rates.

Everything runs in one thread and one process. Each pass steps the vehicle by the physics
steps that are due (:class:`sim_vehicle.clock.SimClock` paces simulated time against the wall
clock at the chosen speed-up), drains the socket, sends the 1 Hz HEARTBEAT and the streams
that are due, and every 0.25 s of wall-clock time does the link's housekeeping; in between it
sleeps in ``select`` until the next step, the next heartbeat or a datagram.
"""

from __future__ import annotations

import dataclasses
import logging
import select

from sim_vehicle.clock import WallTimer
from sim_vehicle.mavlink.server import MavlinkServer

log = logging.getLogger(__name__)

HEARTBEAT_PERIOD_S = 1.0
HOUSEKEEPING_PERIOD_S = 0.25
MAX_PASS_SIM_S = 4
"""At most this many seconds of physics steps in one pass, so that I/O keeps up after a stall."""
MIN_WAKE_PERIOD_S = 0.01
"""The loop wakes at most 100 times a second to step the physics (a datagram wakes it at once)."""
MAX_SLEEP_S = 0.05


class RealtimeLoop:
    """Drives a :class:`MavlinkServer` and its vehicle in real time (times the speed-up).

    Parameters
    ----------
    server : MavlinkServer
        The vehicle's MAVLink side; its clock, autopilot and traffic are stepped here.
    """

    def __init__(self, server: MavlinkServer) -> None:
        self.server = server
        self.clock = server.clock
        self.heartbeat = WallTimer(HEARTBEAT_PERIOD_S, server.wall_s)
        self.housekeeping = WallTimer(HOUSEKEEPING_PERIOD_S, server.wall_s)
        self._stop = False

    def stop(self) -> None:
        """Ask :meth:`run` to return (safe from a signal handler)."""
        self._stop = True

    def run(self, duration_wall_s: float | None = None) -> None:
        """Simulate, receive, send until :meth:`stop` (or for ``duration_wall_s``); log the link statistics."""
        server = self.server
        start = server.wall_s()
        log.info(
            "sim-vehicle sysid %d listening on UDP %s:%d, telemetry to %s and peers; speed-up %g",
            server.sysid,
            server.settings.link.bind_host,
            server.endpoint.port,
            ", ".join(f"{h}:{p}" for h, p in server.endpoint.outs) or "(no --out)",
            self.clock.speedup,
        )
        signing = server.endpoint.signing
        log.info(
            "MAVLink 2 signing: %s",
            f"on, key {signing.fingerprint}"
            if signing.enabled
            else "off" + (", SETUP_SIGNING accepted" if signing.accept_setup else ""),
        )
        while not self._stop:
            if duration_wall_s is not None and server.wall_s() - start >= duration_wall_s:
                break
            self.run_once()
            self._wait()
        log.info("link statistics: %s", dataclasses.asdict(server.stats))

    def run_once(self) -> None:
        """One pass: run due physics, read the socket, send what is due."""
        self._step_vehicle()
        self.server.receive()
        if self.heartbeat.due():
            self.server.on_heartbeat_period()
        self.server.send_due_streams()
        if self.housekeeping.due():
            self.server.housekeeping()

    def _step_vehicle(self) -> None:
        due = self.clock.steps_due()
        if not due:
            return
        server = self.server
        chunk = min(due, MAX_PASS_SIM_S * int(server.settings.timing.physics_rate_hz))
        try:
            events = server.autopilot.run_steps(chunk)
        except Exception as exc:  # never stop flying: log, hold, carry on
            log.exception("simulation step failed")
            server.autopilot.recover(f"{type(exc).__name__}: {exc}")
            events = server.autopilot.run_steps(0)
        self.clock.advance(chunk)
        server.traffic.step(chunk * self.clock.physics_dt_s)
        server.handle_events(events)

    def _wait(self) -> None:
        batch = max(1, int(MIN_WAKE_PERIOD_S * self.clock.speedup / self.clock.physics_dt_s))
        timeout = min(self.clock.wall_until_step_s(batch), self.heartbeat.remaining_s(), MAX_SLEEP_S)
        if timeout > 0:
            select.select([self.server.sock], [], [], timeout)
