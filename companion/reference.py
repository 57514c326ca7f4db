"""The mission clock and the active reference the setpoint stream samples (DESIGN 1, 7).

``VehicleClock`` runs in the vehicle's seconds (``time_boot_ms``), so every trajectory, threat
and decision is on one clock whatever the link's latency and the SITL speed-up.
``ActiveReference`` is a trajectory engaged from a mission time: it turns on the spot first when
asked, holds its end point after its end, and notes when the stream first sampled it (latency).
"""

from __future__ import annotations

import math
import time
from collections import deque

import numpy as np

from companion.link.setpoints import Setpoint
from companion.trajectory import FlyableReference

__all__ = ["VehicleClock", "ActiveReference", "wrap_pi"]


class VehicleClock:
    """Mission time in the vehicle's seconds, extrapolated between its timestamped messages.

    The vehicle stamps LOCAL_POSITION_NED with ``time_boot_ms`` (simulated time in
    ``sim-vehicle``). With ``scale`` vehicle seconds per wall-clock second, every message gives
    a lower bound ``boot_s - scale * arrival`` of the offset between the two clocks (transport
    only delays); the largest over the last ``window_s`` is the estimate. Without messages the
    clock runs at ``scale`` from its creation. The output never goes backwards.
    """

    def __init__(self, scale: float, window_s: float = 2.0):
        self.scale = float(scale)
        self.window_s = window_s
        self._t0 = time.monotonic()
        self._offsets: deque[tuple[float, float]] = deque()
        self._offset: float | None = None
        self._last = -math.inf

    def observe(self, boot_s: float, arrival_monotonic_s: float) -> None:
        if self._offset is None:
            self._last = -math.inf       # switch from the free-running clock to vehicle time
        self._offsets.append((arrival_monotonic_s, boot_s - self.scale * arrival_monotonic_s))
        while self._offsets and self._offsets[0][0] < arrival_monotonic_s - self.window_s:
            self._offsets.popleft()
        self._offset = max(o for _, o in self._offsets)

    @property
    def synced(self) -> bool:
        """True once a vehicle timestamp has been observed (before: free-running)."""
        return self._offset is not None

    def now_s(self, monotonic_s: float | None = None) -> float:
        mono = time.monotonic() if monotonic_s is None else monotonic_s
        if self._offset is None:
            t = self.scale * (mono - self._t0)
        else:
            t = self.scale * mono + self._offset
        self._last = max(self._last, t)
        return self._last


class ActiveReference:
    """A trajectory flown from mission time ``t0_s``; after its end it holds the end point.

    With ``turn_from_yaw_rad`` the vehicle first turns on the spot at the trajectory's start,
    from that heading to the trajectory's initial heading at ``turn_rate_rad_s``, and the
    trajectory starts when the turn is done (a leg that starts at rest in a new direction).
    ``first_sent_monotonic_s`` is set when the stream first samples it (latency measurement).
    ``resume``: the reference stops short of the leg's goal on purpose (an evasion or a hold),
    the flight phases plan back to the mission as soon as it has ended. ``previous``: the
    reference flown until ``t0_s`` when that lies in the future (a decision planned from the
    state its commit time will find, so the setpoint does not jump whatever the decision took).
    """

    def __init__(self, trajectory: FlyableReference, t0_s: float, clock: VehicleClock, path_id: str, *,
                 turn_from_yaw_rad: float | None = None, turn_rate_rad_s: float = 0.6,
                 resume: bool = False, previous: "ActiveReference | None" = None):
        self.trajectory = trajectory
        self.previous = previous
        self.clock = clock
        self.path_id = path_id
        self.resume = resume
        self.first_sent_monotonic_s: float | None = None
        self.turn_from_yaw_rad = turn_from_yaw_rad
        self.turn_rate_rad_s = 0.0
        turn_s = 0.0
        if turn_from_yaw_rad is not None:
            turn = wrap_pi(float(trajectory.yaw_rad(np.array([0.0]))[0]) - turn_from_yaw_rad)
            turn_s = abs(turn) / turn_rate_rad_s
            self.turn_rate_rad_s = math.copysign(turn_rate_rad_s, turn)
        self.turn_start_s = t0_s
        self.t0_s = t0_s + turn_s
        self.t_end_s = self.t0_s + trajectory.duration_s

    def state(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """Position, velocity, acceleration (NED), yaw and yaw rate at mission time ``t_s``."""
        if self.previous is not None:
            if t_s < self.turn_start_s:
                return self.previous.state(t_s)
            self.previous = None
        tau = min(max(t_s - self.t0_s, 0.0), self.trajectory.duration_s)
        at = np.array([tau])
        pos, vel, acc = (v[0] for v in self.trajectory.sample(at))
        if t_s < self.t0_s and self.turn_from_yaw_rad is not None:
            yaw = self.turn_from_yaw_rad + self.turn_rate_rad_s * max(t_s - self.turn_start_s, 0.0)
            return pos, np.zeros(3), np.zeros(3), wrap_pi(yaw), self.turn_rate_rad_s
        yaw = float(self.trajectory.yaw_rad(at)[0])
        if t_s >= self.t_end_s:
            return pos, np.zeros(3), np.zeros(3), yaw, 0.0
        return pos, vel, acc, yaw, float(self.trajectory.yaw_rate_rad_s(at)[0])

    def setpoint_at(self, monotonic_s: float) -> Setpoint:
        """The setpoint streamed at ``monotonic_s`` (the yaw rate as feed-forward)."""
        t_s = self.clock.now_s(monotonic_s)
        if self.first_sent_monotonic_s is None and t_s >= self.turn_start_s:
            self.first_sent_monotonic_s = monotonic_s
        return Setpoint(*self.state(t_s))

    def finished(self, t_s: float) -> bool:
        return t_s >= self.t_end_s

    def end_gap_m(self, goal_ned_m: np.ndarray) -> float:
        """Distance from the trajectory's end point to ``goal_ned_m`` (m, common axes)."""
        end = np.asarray(self.trajectory.end_pos_ned_m, dtype=float)
        n = min(end.shape[0], goal_ned_m.shape[0])
        return float(np.linalg.norm(end[:n] - goal_ned_m[:n]))


def wrap_pi(angle_rad: float) -> float:
    """``angle_rad`` wrapped to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi
