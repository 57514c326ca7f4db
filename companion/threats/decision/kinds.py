"""The words of the threat decision as enums (DESIGN 7.4): what was decided, what a candidate
is, which strategy decides, and what asked for the decision.

``str`` enums (``enum.StrEnum``): a member equals, hashes and formats as its value, so JSON
events, the flight record and comparisons with literals see plain strings.
"""

from __future__ import annotations

import enum

__all__ = ["DecisionKind", "CandidateKind", "Strategy", "Trigger"]


class DecisionKind(enum.StrEnum):
    """What a decision does: ``none`` keeps the active reference; ``rejected`` is an invalid
    threat sample; the others engage a new reference of that kind."""

    NONE = "none"
    REJECTED = "rejected"
    EVADE = "evade"
    HOLD = "hold"
    RETIME = "retime"
    SWITCH = "switch"
    REPLAN = "replan"


class CandidateKind(enum.StrEnum):
    """What a candidate is: ``KEEP`` (``"none"``) is the active reference itself, judged like the
    others; the rest are the strategies' new references (a chosen one becomes the decision's
    kind)."""

    KEEP = "none"
    EVADE = "evade"
    HOLD = "hold"
    RETIME = "retime"
    SWITCH = "switch"
    REPLAN = "replan"


class Strategy(enum.StrEnum):
    """Which candidates a decision considers: ``hybrid`` (DESIGN 7, the default) or one strategy
    alone (the benchmark's comparison)."""

    HYBRID = "hybrid"
    HOLD = "hold"
    RETIME = "retime"
    SWITCH = "switch"
    REPLAN = "replan"
    EVADE = "evade"

    @property
    def switches(self) -> bool:
        """Its candidates include switching to the M-GART alternatives (so they are kept)."""
        return self in (Strategy.HYBRID, Strategy.SWITCH)


class Trigger(enum.StrEnum):
    """What asked for a decision: a threat update, the monitor's tick, or a way back to the
    mission after an evasion or a hold (``resume``)."""

    THREAT = "threat"
    MONITOR = "monitor"
    RESUME = "resume"
