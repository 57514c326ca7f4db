"""What a flight returns: its summary, and the closed-loop figures over its legs."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

log = logging.getLogger(__name__)

__all__ = [
    "CheckerHandle",
    "FlightSummary",
    "feasibility_totals",
    "make_checker",
    "process_checker",
    "warm_process_checker",
]


@dataclass
class FlightSummary:
    """What ``run`` returns and prints."""

    legs_planned: int = 0
    legs_reached: int = 0
    landed: bool = False
    rms_tracking_error_m: float = math.nan
    max_tracking_error_m: float = math.nan
    decisions: int = 0
    min_threat_separation_m: float = math.inf
    latency_ms: dict = field(default_factory=dict)
    fleet: dict = field(default_factory=dict)
    threat_updates: int = 0
    joined: bool = False
    resumed_at_seq: int | None = None
    threats_restored: int = 0
    feasibility: dict = field(default_factory=dict)
    outcome: str = "not flown"

    def as_dict(self) -> dict:
        """Plain data; an infinite separation (no threat met) is None."""
        out = dict(self.__dict__)
        if not math.isfinite(out["min_threat_separation_m"]):
            out["min_threat_separation_m"] = None
        return out


def make_checker(settings):
    """The closed-loop checker of every leg, on the default (R-50-class) model, its LQI
    designed now (about 0.4 s once; cached on the model)."""
    from companion.smoothing.feasibility import FeasibilityChecker
    from heli_model.model import HeliModel

    checker = FeasibilityChecker(HeliModel.default(), settings)
    log.info("feasibility: closed-loop model ready in %.2f s", checker.warm_up())
    return checker


def feasibility_totals(legs) -> dict:
    """The flight's closed-loop figures over its checked legs (empty when none was checked)."""
    checked = [leg.feasibility for leg in legs if leg.feasibility is not None]
    if not checked:
        return {}
    return {
        "legs_checked": len(checked),
        "legs_stretched": sum(1 for f in checked if f["stretch"] > 1.0),
        "legs_infeasible": sum(1 for f in checked if not f["feasible"]),
        "max_stretch": max(f["stretch"] for f in checked),
        "max_abs_delta": max(f["max_abs_delta"] for f in checked),
        "initial_max_abs_delta": max(f["initial_max_abs_delta"] for f in checked),
        "max_tracking_error_m": max(f["max_tracking_error_m"] for f in checked),
        "check_s": sum(f["check_s"] for f in checked),
    }


#: This process's closed-loop checkers, by settings (``process_checker``).
_CHECKERS: dict = {}


def process_checker(settings):
    """The checker of ``settings`` in this process (a planning worker), designed at the first
    call (``make_checker``) and kept: the LQI design does not pickle, and takes seconds."""
    checker = _CHECKERS.get(settings)
    if checker is None:
        checker = _CHECKERS[settings] = make_checker(settings)
    return checker


def warm_process_checker(settings) -> None:
    """Design this worker's checker now (``process_checker``), before the first leg needs it."""
    process_checker(settings)


class CheckerHandle:
    """Stands for a planning worker's own checker of ``settings``: it pickles as a call of
    ``process_checker``, so what a worker process receives is its cached checker."""

    def __init__(self, settings) -> None:
        self.settings = settings

    def __reduce__(self):
        return process_checker, (self.settings,)
