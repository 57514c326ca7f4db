"""Simulated time paced against the wall clock, with a speed-up (DESIGN section 5).

The simulation runs in whole physics steps. :meth:`SimClock.steps_due` says how many steps
should have run by now so that simulated time equals ``speedup`` times the elapsed wall time;
the caller runs them and calls :meth:`advance`. When the host cannot keep up (or the process
was stopped), the clock slips by the lag instead of catching up in a burst, and counts the
slip. Heartbeats and peer timeouts use the wall clock (:class:`WallTimer`) so that a ground
station sees 1 Hz heartbeats whatever the speed-up, as ArduPilot's SITL does.

The wall clock is injected (``wall_s`` callable), so the pacing is tested without sleeping.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

log = logging.getLogger(__name__)


class SimClock:
    """Simulated time in whole physics steps, paced at ``speedup`` x the wall clock.

    Parameters
    ----------
    physics_dt_s : float
        One physics step, simulated seconds.
    speedup : float
        Simulated seconds per wall second.
    max_lag_s : float
        Largest backlog (wall seconds) that is caught up; beyond it the clock slips.
    wall_s : callable, optional
        Monotonic wall clock in seconds (default ``time.monotonic``).
    """

    def __init__(
        self,
        physics_dt_s: float,
        speedup: float = 1.0,
        max_lag_s: float = 0.5,
        wall_s: Callable[[], float] = time.monotonic,
    ) -> None:
        if not physics_dt_s > 0.0:
            raise ValueError(f"physics_dt_s: expected > 0, got {physics_dt_s!r}")
        self.physics_dt_s = float(physics_dt_s)
        self.max_lag_s = float(max_lag_s)
        self._wall_s = wall_s
        self._speedup = 1.0
        self.steps = 0
        self.slipped_wall_s = 0.0
        self.slips = 0
        self._last_slip_log_s = -math.inf
        self._anchor_wall_s = wall_s()
        self._anchor_steps = 0
        self.set_speedup(speedup)

    @property
    def speedup(self) -> float:
        """Simulated seconds per wall second."""
        return self._speedup

    @property
    def time_s(self) -> float:
        """Simulated time since start, s."""
        return self.steps * self.physics_dt_s

    def wall_s(self) -> float:
        """The wall clock, s."""
        return self._wall_s()

    def set_speedup(self, speedup: float) -> None:
        """Change the speed-up from now on (re-anchors the pacing; no jump in simulated time)."""
        if not (speedup > 0.0):
            raise ValueError(f"speedup: expected > 0, got {speedup!r}")
        self._anchor_wall_s = self._wall_s()
        self._anchor_steps = self.steps
        self._speedup = float(speedup)

    def _target_steps(self, now_wall_s: float) -> float:
        return self._anchor_steps + (now_wall_s - self._anchor_wall_s) * self._speedup / self.physics_dt_s

    def steps_due(self) -> int:
        """Physics steps to run now to be on time (slips first if too far behind)."""
        now = self._wall_s()
        behind = self._target_steps(now) - self.steps
        lag_wall_s = behind * self.physics_dt_s / self._speedup
        if lag_wall_s > self.max_lag_s:
            slip = lag_wall_s - self.max_lag_s
            self.slipped_wall_s += slip
            self.slips += 1
            self._anchor_wall_s += slip
            if now - self._last_slip_log_s >= 10.0:  # at most one line per 10 s
                self._last_slip_log_s = now
                log.warning(
                    "simulation %.3f s (wall) behind: slipping; the host cannot run %.3g x real time "
                    "(%d slips, %.1f s lost so far)",
                    lag_wall_s,
                    self._speedup,
                    self.slips,
                    self.slipped_wall_s,
                )
            behind = self._target_steps(now) - self.steps
        return max(0, int(behind + 1e-6))  # tolerate float rounding of the wall clock

    def advance(self, steps: int) -> None:
        """Record that ``steps`` physics steps were run."""
        self.steps += int(steps)

    def wall_until_step_s(self, steps_ahead: int = 1) -> float:
        """Wall seconds until ``steps_ahead`` more steps are due (0 if already due)."""
        target = self.steps + steps_ahead
        wall_at = self._anchor_wall_s + (target - self._anchor_steps) * self.physics_dt_s / self._speedup
        return max(0.0, wall_at - self._wall_s())


class WallTimer:
    """A periodic deadline on the wall clock (e.g. the 1 Hz heartbeat).

    Parameters
    ----------
    period_s : float
        Wall seconds between firings.
    wall_s : callable
        The wall clock.
    """

    def __init__(self, period_s: float, wall_s: Callable[[], float] = time.monotonic) -> None:
        self.period_s = float(period_s)
        self._wall_s = wall_s
        self.next_s = wall_s()

    def due(self) -> bool:
        """True (and schedules the next firing) when the deadline has passed."""
        now = self._wall_s()
        if now < self.next_s:
            return False
        self.next_s += self.period_s
        if self.next_s < now:  # missed several: do not fire in a burst
            self.next_s = now + self.period_s
        return True

    def remaining_s(self) -> float:
        """Wall seconds until the next firing (0 if due)."""
        return max(0.0, self.next_s - self._wall_s())
