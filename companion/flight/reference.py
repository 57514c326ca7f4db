"""The mission clock and the active reference the setpoint stream samples (DESIGN 1, 7).

``VehicleClock`` runs in the vehicle's seconds (``time_boot_ms``), so every trajectory, threat
and decision is on one clock whatever the link's latency and the SITL speed-up.
``ActiveReference`` is a trajectory engaged from a mission time: it turns on the spot first when
asked, holds its end point after its end, and notes when the stream first sampled it (latency).

The stream (50 Hz), the tracking error (every LOCAL_POSITION_NED) and the record's samples ask
the reference for its state about a hundred times a wall-clock second. Evaluating the smoothed
trajectory for one instant costs about a millisecond of numpy overhead, so ``ReferenceTable``
evaluates it for ten seconds of knots at once (``TABLE_STEP_S`` apart: 2.2 ms of CPU, against
1.6 ms for one second) and interpolates between them: cubic Hermite for the position (from the
velocity) and the velocity (from the acceleration), linear for the acceleration, the yaw
(unwrapped) and the yaw rate. At the knots the values are the trajectory's own; between them, on
the demo mission's legs, the position is within 5 micrometres and the velocity within 1 mm/s; an
acceleration or yaw rate that steps (where the speed profile changes phase) is ramped over the
20 ms interval that holds the step.
The stream evaluates the next chunk ahead of need, right after a send
(``ActiveReference.prepare``), so a chunk's evaluation never delays a setpoint.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from companion.flight.setpoint import Setpoint
from companion.flight.trajectory import FlyableReference

__all__ = ["MissionClock", "VehicleClock", "ActiveReference", "ReferenceTable", "wrap_pi"]

#: Spacing of the knots of ``ReferenceTable`` (trajectory s).
TABLE_STEP_S = 0.02
#: Knots evaluated at once (ten seconds of trajectory at ``TABLE_STEP_S``).
TABLE_CHUNK_KNOTS = 500
#: Chunks kept: the stream's, the next one (``prepare``), the record's or the tracking error's
#: (a little behind), and the M-GART refresh's start (a little ahead).
TABLE_CHUNKS_KEPT = 3
#: ``ActiveReference.prepare`` evaluates the chunk this far ahead of the last setpoint (s).
PREPARE_AHEAD_S = 1.0
_ZERO3 = (0.0, 0.0, 0.0)


class MissionClock(Protocol):
    """Mission time now, or of a monotonic instant: a :class:`VehicleClock`, or fast time's
    ``VirtualClock`` (``companion.flight.fast_time``)."""

    def now_s(self, monotonic_s: float | None = None) -> float: ...


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
            self._last = -math.inf  # switch from the free-running clock to vehicle time
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


class ReferenceTable:
    """A trajectory's state at any time in [0, duration], from knots evaluated a chunk at a
    time (see the module docstring).

    Parameters
    ----------
    trajectory : FlyableReference
    step_s : float
        Knot spacing (trajectory s).
    chunk_knots : int
        Knots per evaluated chunk; the two chunks used last are kept.
    """

    def __init__(
        self, trajectory: FlyableReference, step_s: float = TABLE_STEP_S, chunk_knots: int = TABLE_CHUNK_KNOTS
    ):
        self.trajectory = trajectory
        self.duration_s = float(trajectory.duration_s)
        self.step_s = float(step_s)
        self.chunk_knots = int(chunk_knots)
        self._chunks: dict[int, tuple] = {}

    def _chunk(self, index: int) -> tuple:
        """Knot times (K,), positions, velocities, accelerations (K, d), yaw (unwrapped) and
        yaw rate (K,) of chunk ``index``, as Python lists (one query is a handful of float
        operations: numpy's per-call cost would be most of it)."""
        chunk = self._chunks.get(index)
        if chunk is None:
            first = index * self.chunk_knots
            tau = np.minimum((first + np.arange(self.chunk_knots + 1)) * self.step_s, self.duration_s)
            tau = np.unique(tau)
            pos, vel, acc = (np.asarray(v, dtype=float) for v in self.trajectory.sample(tau))
            yaw = np.unwrap(np.asarray(self.trajectory.yaw_rad(tau), dtype=float))
            rate = np.asarray(self.trajectory.yaw_rate_rad_s(tau), dtype=float)
            chunk = tuple(a.tolist() for a in (tau, pos, vel, acc, yaw, rate))
            if len(self._chunks) >= TABLE_CHUNKS_KEPT:
                self._chunks.pop(next(iter(self._chunks)))
            self._chunks[index] = chunk
        return chunk

    def _chunk_index(self, tau_s: float) -> int:
        span_s = self.step_s * self.chunk_knots
        return min(int(tau_s / span_s), int(self.duration_s / span_s))

    def prepare(self, tau_s: float) -> None:
        """Evaluate the chunk that holds trajectory time ``tau_s`` now, if not yet done."""
        self._chunk(self._chunk_index(min(max(float(tau_s), 0.0), self.duration_s)))

    def state(self, tau_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """Position, velocity, acceleration, yaw (wrapped) and yaw rate at trajectory time
        ``tau_s`` (clamped to [0, duration])."""
        p, v, a, yaw, rate = self.state_lists(tau_s)
        return np.array(p), np.array(v), np.array(a), yaw, rate

    def state_lists(self, tau_s: float) -> tuple[list, list, list, float, float]:
        """``state`` with the vectors as lists of d floats (the setpoint stream's fast path)."""
        tau_s = min(max(float(tau_s), 0.0), self.duration_s)
        tau, pos, vel, acc, yaw, rate = self._chunk(self._chunk_index(tau_s))
        i = min(max(int((tau_s - tau[0]) / self.step_s), 0), len(tau) - 1)
        while i > 0 and tau[i] > tau_s:
            i -= 1
        if i == len(tau) - 1 or tau[i + 1] <= tau[i]:
            return pos[i], vel[i], acc[i], wrap_pi(yaw[i]), rate[i]
        h = tau[i + 1] - tau[i]
        u = (tau_s - tau[i]) / h
        p = _hermite(pos[i], pos[i + 1], vel[i], vel[i + 1], h, u)
        v = _hermite(vel[i], vel[i + 1], acc[i], acc[i + 1], h, u)
        a = [a0 + u * (a1 - a0) for a0, a1 in zip(acc[i], acc[i + 1])]
        return p, v, a, wrap_pi(yaw[i] + u * (yaw[i + 1] - yaw[i])), rate[i] + u * (rate[i + 1] - rate[i])


def _hermite(p0: list, p1: list, d0: list, d1: list, h: float, u: float) -> list:
    """Cubic Hermite interpolation at ``u`` in [0, 1] between values ``p0``, ``p1`` with
    derivatives ``d0``, ``d1`` over an interval of length ``h``."""
    u2, u3 = u * u, u * u * u
    c0, c1, c2, c3 = 2 * u3 - 3 * u2 + 1, (u3 - 2 * u2 + u) * h, -2 * u3 + 3 * u2, (u3 - u2) * h
    return [c0 * a + c1 * da + c2 * b + c3 * db for a, b, da, db in zip(p0, p1, d0, d1)]


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

    def __init__(
        self,
        trajectory: FlyableReference,
        t0_s: float,
        clock: MissionClock,
        path_id: str,
        *,
        turn_from_yaw_rad: float | None = None,
        turn_rate_rad_s: float = 0.6,
        resume: bool = False,
        previous: ActiveReference | None = None,
    ):
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
        self.table = ReferenceTable(trajectory)
        self._end_gap: tuple[tuple, float] | None = None  # (goal, end_gap_m)
        self._last_sampled_s: float | None = None

    def state(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """Position, velocity, acceleration (NED), yaw and yaw rate at mission time ``t_s``."""
        p, v, a, yaw, rate = self.state_lists(t_s)
        return np.array(p), np.array(v), np.array(a), yaw, rate

    def state_lists(self, t_s: float) -> tuple[Sequence[float], Sequence[float], Sequence[float], float, float]:
        """``state`` with the vectors as sequences of 3 floats (the setpoint stream's fast path)."""
        if self.previous is not None:
            if t_s < self.turn_start_s:
                return self.previous.state_lists(t_s)
            self.previous = None
        pos, vel, acc, yaw, rate = self.table.state_lists(t_s - self.t0_s)
        if t_s < self.t0_s and self.turn_from_yaw_rad is not None:
            yaw = self.turn_from_yaw_rad + self.turn_rate_rad_s * max(t_s - self.turn_start_s, 0.0)
            return pos, _ZERO3, _ZERO3, wrap_pi(yaw), self.turn_rate_rad_s
        if t_s >= self.t_end_s:
            return pos, _ZERO3, _ZERO3, yaw, 0.0
        return pos, vel, acc, yaw, rate

    def setpoint_at(self, monotonic_s: float) -> Setpoint:
        """The setpoint streamed at ``monotonic_s`` (the yaw rate as feed-forward)."""
        t_s = self.clock.now_s(monotonic_s)
        if self.first_sent_monotonic_s is None and t_s >= self.turn_start_s:
            self.first_sent_monotonic_s = monotonic_s
        self._last_sampled_s = t_s
        return Setpoint(*self.state_lists(t_s))

    def prepare(self) -> None:
        """Evaluate ahead the part of the trajectory the stream will need ``PREPARE_AHEAD_S``
        after its last setpoint (the stream calls it right after a send)."""
        if self._last_sampled_s is not None:
            self.table.prepare(self._last_sampled_s + PREPARE_AHEAD_S - self.t0_s)

    def finished(self, t_s: float) -> bool:
        return t_s >= self.t_end_s

    def end_gap_m(self, goal_ned_m: np.ndarray) -> float:
        """Distance from the trajectory's end point to ``goal_ned_m`` (m, common axes);
        computed once per goal (the phase machine asks at every step)."""
        key = tuple(np.asarray(goal_ned_m, dtype=float).tolist())
        if self._end_gap is None or self._end_gap[0] != key:
            end = np.asarray(self.trajectory.end_pos_ned_m, dtype=float).tolist()
            n = min(len(end), len(key))
            self._end_gap = (key, math.dist(end[:n], key[:n]))
        return self._end_gap[1]


def wrap_pi(angle_rad: float) -> float:
    """``angle_rad`` wrapped to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi
