"""Committing a new trajectory among other vehicles: RMADER's delay check (DESIGN 6, 7).

A new trajectory was chosen against the others' trajectories known when the decision started.
It is published as *pending* (the others avoid it too, when we have priority), then, after a
wait that covers the communication delay, checked again against what arrived meanwhile. It is
flown only when that check finds no conflict with another vehicle that the first one did not
(a decision that knowingly accepted an intrusion, the best of bad choices, is not refused for
it unless the intrusion got deeper by ``WORSE_BY_M``).

Pure: ``fleet_conflict`` and ``refuses`` are numpy only; the waiting is the caller's.
"""

from __future__ import annotations

import numpy as np

from companion.threats.decision.prediction import predict_tubes
from companion.threats.decision.spacetime import BatchCheck, check_candidates, sample_times

__all__ = ["fleet_check", "refuses", "WORSE_BY_M"]

#: After the wait, an accepted intrusion may not have become deeper than this (m).
WORSE_BY_M = 0.5


def fleet_check(
    trajectory, start_t_s: float, now_t_s: float, threats, *, horizon_s: float, step_s: float, inflation_m: float
) -> BatchCheck:
    """Check ``trajectory`` (t = 0 at ``start_t_s``) from ``now_t_s`` over ``horizon_s`` against
    the tubes of the other vehicles ``threats`` (``VehicleThreat``) only."""
    t = sample_times(now_t_s, horizon_s, step_s)
    pos = np.atleast_2d(trajectory.sample(np.clip(t - start_t_s, 0.0, None))[0])
    return check_candidates(t, pos[None], predict_tubes(threats, inflation_m=inflation_m))


def refuses(before: BatchCheck, after: BatchCheck) -> bool:
    """True when the check after the wait found a conflict the one before did not."""
    if bool(after.clear[0]):
        return False
    if bool(before.clear[0]):
        return True
    return float(after.min_clearance_m[0]) < float(before.min_clearance_m[0]) - WORSE_BY_M
