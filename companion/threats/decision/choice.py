"""Decide (DESIGN 7.4): candidates, their one cost, and the decision record.

Every strategy turns the situation into ``Candidate`` trajectories; all of them are judged by
the same space-time check (``spacetime.check_candidates``) and the same cost:

1. clear candidates before candidates that intrude (clearance first);
2. among clear ones the least ``cost_s``: the estimated time to the leg's goal (delay and
   deviation in one unit: an evasion that ends in a hover pays the way back at cruise speed
   plus ``restart_s``) minus a bonus for clearance, ``clearance_weight_s_m`` per metre up to
   ``clearance_cap_m`` (so a comfortable margin wins over a marginal one of similar cost);
3. among intruding ones, those that keep off the static obstacles (a hard constraint; a
   threat's inflation is a margin), then the largest minimum clearance, then the least
   intrusion integral.

Pure: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from companion.threats.decision.kinds import CandidateKind, DecisionKind
from companion.threats.decision.spacetime import Conflict

__all__ = ["ReferenceState", "Candidate", "Decision", "choose", "intruding_key"]


@dataclass(frozen=True)
class ReferenceState:
    """The reference (setpoint) at time ``t_s``: where a new trajectory must start.

    Attributes
    ----------
    t_s : float
        Time on the manager's clock (s).
    pos_ned_m, vel_ned_m_s, acc_ned_m_s2 : ndarray, shape (D,)
        D is the active trajectory's dimension (3 in flight).
    yaw_rad : float
    """

    t_s: float
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    acc_ned_m_s2: np.ndarray
    yaw_rad: float = 0.0


@dataclass
class Candidate:
    """One possible new reference, judged by the space-time check and the cost.

    Attributes
    ----------
    kind : CandidateKind
        ``retime``, ``switch``, ``replan``, ``evade`` or ``hold`` (``none``: the active
        reference kept); a string is converted.
    label : str
        Short words for the operator (``evade left + climb``).
    trajectory : Trajectory-like
        t = 0 at the decision's reference time.
    time_to_goal_s : float
        Estimated time from now to the leg's goal along this candidate (s).
    path_id : str
    path_ned_m : ndarray (M, d) or None
    clear, min_clearance_m, intrusion_m2s, conflict, static_clearance_m
        Filled by the check.
    ends_short : bool
        The candidate stops short of the goal (a plan back is needed after it).
    """

    kind: CandidateKind
    label: str
    trajectory: object
    time_to_goal_s: float
    path_id: str = ""
    path_ned_m: np.ndarray | None = None
    clear: bool = False
    min_clearance_m: float = -math.inf
    intrusion_m2s: float = math.inf
    conflict: Conflict | None = None
    ends_short: bool = False
    static_clearance_m: float = math.inf

    def __post_init__(self) -> None:
        self.kind = CandidateKind(self.kind)

    def judged(self, check, i: int) -> Candidate:
        """Take candidate ``i``'s result from a ``BatchCheck``."""
        self.clear, self.min_clearance_m = bool(check.clear[i]), float(check.min_clearance_m[i])
        self.intrusion_m2s, self.conflict = float(check.intrusion_m2s[i]), check.conflicts[i]
        self.static_clearance_m = float(check.static_clearance_m[i])
        return self

    def cost_s(self, clearance_weight_s_m: float, clearance_cap_m: float) -> float:
        """Time to goal minus the clearance bonus (s)."""
        bonus = clearance_weight_s_m * min(max(self.min_clearance_m, 0.0), clearance_cap_m)
        return self.time_to_goal_s - bonus


def rank_key(c: Candidate, clearance_weight_s_m: float, clearance_cap_m: float) -> tuple:
    """Sort key: clear first by cost; then those that keep off the static obstacles (hard), by
    clearance (0.1 m steps), then by intrusion."""
    if c.clear:
        return (0, False, c.cost_s(clearance_weight_s_m, clearance_cap_m), 0.0)
    return intruding_key(c.static_clearance_m, c.min_clearance_m, c.intrusion_m2s)


def intruding_key(static_clearance_m: float, min_clearance_m: float, intrusion_m2s: float) -> tuple:
    """Sort key of a candidate that is not clear (see ``rank_key``)."""
    return (1, static_clearance_m < 0.0, -round(min_clearance_m, 1), intrusion_m2s)


def choose(candidates, clearance_weight_s_m: float, clearance_cap_m: float) -> Candidate | None:
    """The best candidate (see the module docstring), None for an empty list."""
    if not candidates:
        return None
    return min(candidates, key=lambda c: rank_key(c, clearance_weight_s_m, clearance_cap_m))


@dataclass(frozen=True)
class Decision:
    """What the manager decided.

    Attributes
    ----------
    kind : DecisionKind
        A string is converted (``none`` keeps the active reference).
    reason : str
        Why, in words (logged and published in the ``events`` message).
    trajectory : Trajectory-like or None
        The new reference: engage it so that its time 0 is ``start_t_s`` on the manager's clock
        (the reference state it was built from), which keeps the setpoint continuous whatever
        the decision latency.
    start_t_s : float or None
    path_id : str or None
    path_ned_m : ndarray (M, d) or None
        The polyline of the new reference (for ``uav/<sysid>/path``).
    conflict : Conflict or None
        The conflict of the active reference that triggered the decision.
    decide_ms, plan_ms : float
        Wall-clock duration of the decision and of its candidate generation (ms).
    resume : bool
        The new reference stops short of the goal (an evasion or a hold): once it has ended,
        call ``resume`` to plan back to the mission. With kind ``none`` after ``resume``: no
        clear way back yet, ask again later.
    label : str
        Short words for the operator's STATUSTEXT (``evade left``, ``switch alt1-3``).
    candidates : dict
        How many candidates of each kind were judged.
    min_clearance_m : float
        The chosen candidate's minimum clearance over the horizon (m; negative: it intrudes).
    branch : str
        How it was decided: ``fast`` (the fast step: milliseconds), ``replan`` (the conflict was
        far enough to replan first: the candidates start after the fast step and a replan, and
        an evasion chosen then took that long) or ``resume`` (a way back to the mission).
    """

    kind: DecisionKind
    reason: str
    trajectory: object = None
    start_t_s: float | None = None
    path_id: str | None = None
    path_ned_m: np.ndarray | None = None
    conflict: Conflict | None = None
    decide_ms: float = 0.0
    plan_ms: float = 0.0
    resume: bool = False
    label: str = ""
    candidates: dict = field(default_factory=dict)
    min_clearance_m: float = math.inf
    branch: str = "fast"

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", DecisionKind(self.kind))

    def as_event(self) -> dict:
        """The ``uav/<sysid>/events`` message of this decision (without the transport latency);
        kinds as plain strings."""
        kind = self.kind.value
        out = {
            "event": kind,
            "reason": self.reason,
            "path_id": self.path_id,
            "label": self.label or kind,
            "decide_ms": round(self.decide_ms, 3),
            "plan_ms": round(self.plan_ms, 3),
            "branch": self.branch,
            "candidates": {str(k): int(n) for k, n in self.candidates.items()},
            "min_clearance_m": (round(self.min_clearance_m, 3) if math.isfinite(self.min_clearance_m) else None),
        }
        if self.conflict is not None:
            out["threat_id"] = self.conflict.threat_id
            out["time_to_conflict_s"] = round(self.conflict.time_to_conflict_s, 3)
        return out
