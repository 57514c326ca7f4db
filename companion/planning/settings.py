"""Planner settings (frozen dataclasses with documented defaults), loaded by ``companion.config``.

Paper section 3.1 (GART: guided sampling, steering, RRT* rewiring), 3.2 (the G2 corner that
bounds the heading change) and 3.3 (M-GART, *Extending Forbidden*). Distances in metres,
angles in radians, times in seconds.

Heading limit and the G2 smoother. A corner of deflection ``gamma`` between two straight edges
is replaced by the G2 cubic Bezier spiral pair, which uses a length

    d = 1.1228 sin(beta) / (K_max cos(beta)^2),   beta = gamma / 2

along each edge (Yang and Sukkarieh; paper eqs. 15-19). When ``kappa_max_1_m`` is set, GART
accepts a corner only if ``d <= corner_fraction * min(L_in, L_out)`` for the two edge lengths, so
consecutive corners never overlap and the smoother can honour K_max everywhere; independently,
``max_heading_change_rad`` caps ``gamma`` (default 135 deg).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from companion.errors import PlanningError

__all__ = ["CostWeights", "GartSettings", "MgartSettings", "SimplifySettings", "G2_CORNER_COEFF"]

#: Coefficient of the G2 cubic-spiral corner length d = c sin(beta) / (K_max cos^2 beta).
G2_CORNER_COEFF = 1.1228


@dataclass(frozen=True)
class CostWeights:
    """Weights of the paper's cost (eq. 3): energy + threat + tracking.

    Attributes
    ----------
    energy : float
        Weight of the energy term, per metre of path (default 1).
    climb_penalty : float
        Extra energy per metre climbed (a decrease of *down*), 3D only (default 1: climbing a
        metre costs as much as flying two).
    threat : float
        Weight of the threat term: integral over the path of ``(1 - c / threat_range_m)^2`` for
        clearance ``c < threat_range_m`` (m of "threat exposure"; default 0).
    threat_range_m : float
        Clearance (m) beyond which an obstacle adds no threat cost (default 5).
    tracking_m_per_rad : float
        Weight of the tracking term, the sum of heading changes at the corners (default 0).
    """

    energy: float = 1.0
    climb_penalty: float = 1.0
    threat: float = 0.0
    threat_range_m: float = 5.0
    tracking_m_per_rad: float = 0.0

    def __post_init__(self):
        for name in ("energy", "climb_penalty", "threat", "tracking_m_per_rad"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise PlanningError(f"cost.{name}: must be a finite number >= 0, got {v!r}")
        if self.energy <= 0:
            raise PlanningError(f"cost.energy: must be > 0, got {self.energy!r}")
        if not (math.isfinite(self.threat_range_m) and self.threat_range_m > 0):
            raise PlanningError(f"cost.threat_range_m: must be > 0, got {self.threat_range_m!r}")

    @classmethod
    def length_only(cls) -> CostWeights:
        """Cost = path length in metres (what OMPL's planners minimise; used by benchmarks)."""
        return cls(energy=1.0, climb_penalty=0.0, threat=0.0, tracking_m_per_rad=0.0)


@dataclass(frozen=True)
class SimplifySettings:
    """Shortcutting of the final path (kept apart from the planner, like OMPL's simplifier).

    Attributes
    ----------
    enabled : bool
        Shortcut the returned path (default True). Shortcuts keep the heading limit.
    max_rounds : int
        Passes of greedy shortcutting (default 3).
    """

    enabled: bool = True
    max_rounds: int = 3


@dataclass(frozen=True)
class GartSettings:
    """GART settings (paper section 3.1). Distances in metres.

    Attributes
    ----------
    step_m : float
        Steering step: maximum length of a new edge (default 20; OMPL RRT* range in the anchors: 28.3).
    goal_bias : float
        Probability of sampling the goal itself (default 0.1).
    rewire_factor : float
        Multiplier of the RRT* optimal radius gamma* (default 1.1, as OMPL).
    max_rewire_radius_m : float or None
        Cap of the shrinking neighbour radius (default None: ``2 * step_m``).
    goal_radius_m : float or None
        A new node this close to the goal tries a direct edge to it (default None: ``step_m``).
    goal_gain_m : float
        Goal attraction: a sample moves this far towards the goal (default 1.5).
    obstacle_gain_m2 : float
        Obstacle attraction gain k: an outside sample at clearance c moves ``k / c`` towards the
        obstacle surface, at most ``c / 2`` (default 4).
    influence_m : float
        Obstacles farther than this (clearance) do not act on a sample (default 6).
    repel_offset_m : float
        A sample inside an inflated obstacle is pushed this far beyond its surface (default 0.5).
    max_guidance_m : float
        Cap of the total displacement of a sample (default 6).
    guidance : bool
        Apply the potential to the random samples (default True: GART; False: plain RRT*).
    informed : bool
        Once a path exists, sample the prolate hyperspheroid that can still improve it (default True).
    kappa_max_1_m : float or None
        Vehicle K_max (1/m); with it, corners are limited so the G2 corner fits (module docstring).
    max_heading_change_rad : float
        Largest heading change at a corner (default 3/4 pi).
    corner_fraction : float
        Share of the shorter adjacent edge a G2 corner may use (default 0.5).
    time_budget_s : float
        Wall-clock budget when the caller gives neither ``max_time_s`` nor ``max_iterations``.
    cost : CostWeights
        Cost weights (paper eq. 3).
    simplify : SimplifySettings
        Final path shortcutting.
    """

    step_m: float = 20.0
    goal_bias: float = 0.1
    rewire_factor: float = 1.1
    max_rewire_radius_m: float | None = None
    goal_radius_m: float | None = None
    goal_gain_m: float = 1.5
    obstacle_gain_m2: float = 4.0
    influence_m: float = 6.0
    repel_offset_m: float = 0.5
    max_guidance_m: float = 6.0
    guidance: bool = True
    informed: bool = True
    kappa_max_1_m: float | None = None
    max_heading_change_rad: float = 0.75 * math.pi
    corner_fraction: float = 0.5
    time_budget_s: float = 1.0
    cost: CostWeights = field(default_factory=CostWeights)
    simplify: SimplifySettings = field(default_factory=SimplifySettings)

    def __post_init__(self):
        def positive(name):
            v = getattr(self, name)
            if v is None:
                return
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise PlanningError(f"settings.{name}: must be a positive finite number, got {v!r}")

        for name in (
            "step_m",
            "rewire_factor",
            "max_rewire_radius_m",
            "goal_radius_m",
            "influence_m",
            "max_guidance_m",
            "kappa_max_1_m",
            "time_budget_s",
            "corner_fraction",
        ):
            positive(name)
        for name in ("goal_gain_m", "obstacle_gain_m2", "repel_offset_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise PlanningError(f"settings.{name}: must be a finite number >= 0, got {v!r}")
        if not 0.0 <= self.goal_bias <= 1.0:
            raise PlanningError(f"settings.goal_bias: must be in [0, 1], got {self.goal_bias!r}")
        if not 0.0 < self.max_heading_change_rad <= math.pi:
            raise PlanningError(
                f"settings.max_heading_change_rad: must be in (0, pi], got {self.max_heading_change_rad!r}"
            )

    def max_heading_change_for(self, edge_length_m: float) -> float:
        """Largest corner deflection (rad) allowed between two edges of ``edge_length_m``."""
        limit = self.max_heading_change_rad
        if self.kappa_max_1_m is None:
            return limit
        room = self.corner_fraction * edge_length_m * self.kappa_max_1_m / G2_CORNER_COEFF
        # solve sin(b) / cos(b)^2 = room for b in (0, pi/2): sin b = (-1 + sqrt(1 + 4 room^2)) / (2 room)
        s = (-1.0 + math.sqrt(1.0 + 4.0 * room * room)) / (2.0 * room)
        return min(limit, 2.0 * math.asin(min(s, 1.0)))


@dataclass(frozen=True)
class MgartSettings:
    """M-GART settings (paper section 3.3, *Extending Forbidden*).

    Attributes
    ----------
    gart : GartSettings
        Settings of the underlying GART tree.
    keep_near_root_m : float
        Forbidden branches stay extendable within this distance of the start, so new branches
        can still leave it (default 10).
    min_separation_m : float
        Two paths are distinct when their discrete Hausdorff distance (paths resampled every
        ``separation_sample_m``) is at least this (default 4).
    separation_sample_m : float
        Resampling step of the distinctness measure (default 1).
    forbid_tube_m : float
        Nodes within this distance of a finished branch are forbidden with it (default 4;
        0 = only the branch, the paper's rule).
    portal_zone_m : float
        Waypoints of kept paths within this distance of the goal stay open as goal portals
        that later branches may join (:mod:`companion.planning.portals`; default 40, twice the
        default step; 0 = none, the paper's rule).
    time_budget_s : float
        Budget when the caller gives no ``max_time_s`` (default 0.5).
    """

    gart: GartSettings = field(default_factory=GartSettings)
    keep_near_root_m: float = 10.0
    min_separation_m: float = 4.0
    separation_sample_m: float = 1.0
    forbid_tube_m: float = 4.0
    portal_zone_m: float = 40.0
    time_budget_s: float = 0.5

    def __post_init__(self):
        for name in ("keep_near_root_m", "min_separation_m", "separation_sample_m", "time_budget_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise PlanningError(f"settings.{name}: must be a positive finite number, got {v!r}")
        for name in ("forbid_tube_m", "portal_zone_m"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
                raise PlanningError(f"settings.{name}: must be >= 0, got {v!r}")
