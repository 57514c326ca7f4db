"""The corner rule and the edge cost of the compiled iteration (numba), as the Python planner computes them.

:meth:`~companion.planning.simplify.CornerRule.ok` limits the heading change at a corner and,
with K_max, asks for room for a G2 corner (its tangent length against the shorter edge) and a
collision-free one (two segment tests at the corner); :meth:`~companion.planning.cost.EdgeCost.edge`
without threat term is the length plus the climb penalty, times the energy weight.
:func:`corner_fits` (the rule without the corner's segment tests), :func:`corner_clear` (with
them) and :func:`edge_cost` do the same floating-point operations in the same order, so the
compiled planner takes the Python planner's decisions.

``rule`` is the tuple ``(cos_max, kappa_1_m, corner_fraction, g2_coeff)`` of :func:`rule_of`,
``kappa_1_m`` 0 without K_max; ``space`` the world's obstacles
(:func:`~companion.world.obstacle_kernels.space_of`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from companion.planning.settings import G2_CORNER_COEFF, GartSettings
from companion.world import obstacle_kernels as okern

__all__ = ["rule_of", "climb_penalty_of", "corner_fits", "corner_clear", "edge_cost"]


def rule_of(settings: GartSettings) -> tuple:
    """``(cos_max, kappa_1_m or 0.0, corner_fraction, G2_CORNER_COEFF)`` of ``settings``."""
    kappa = settings.kappa_max_1_m
    return (
        math.cos(settings.max_heading_change_rad),
        0.0 if kappa is None else float(kappa),
        float(settings.corner_fraction),
        float(G2_CORNER_COEFF),
    )


def climb_penalty_of(settings: GartSettings, dim: int) -> float:
    """The climb penalty ``EdgeCost`` applies (0.0 when it applies none: 2D, or a zero weight)."""
    pen = float(settings.cost.climb_penalty)
    return pen if pen > 0.0 and dim == 3 else 0.0


@njit(cache=True)
def _need(u_in, len_in: float, u_out, len_out: float, rule) -> tuple[int, float]:
    """``(verdict, need)``: verdict 0 refused, 1 allowed, 2 allowed if the corner (tangent ``need``) is clear."""
    cos_max, kappa, fraction, coeff = rule
    c = 0.0
    for k in range(u_in.shape[0]):
        c += u_in[k] * u_out[k]
    if c < cos_max:
        return 0, 0.0
    if kappa == 0.0 or c >= 1.0 - 1e-12:
        return 1, 0.0
    sin_beta = math.sqrt(0.5 * (1.0 - c))
    cos2_beta = 0.5 * (1.0 + c)
    need = coeff * sin_beta / (kappa * cos2_beta)
    if need > fraction * (len_in if len_in < len_out else len_out):
        return 0, 0.0
    return 2, need


@njit(cache=True)
def corner_fits(u_in, len_in: float, u_out, len_out: float, rule) -> bool:
    """``CornerRule.ok(u_in, len_in, u_out, len_out)`` (no corner point: no segment test)."""
    return _need(u_in, len_in, u_out, len_out, rule)[0] > 0


@njit(cache=True)
def corner_clear(u_in, len_in: float, u_out, len_out: float, corner, rule, space) -> bool:
    """``CornerRule.ok(u_in, len_in, u_out, len_out, corner)`` with K_max's two segment tests."""
    verdict, need = _need(u_in, len_in, u_out, len_out, rule)
    if verdict < 2:
        return verdict == 1
    d = corner.shape[0]
    b0 = np.empty(d)
    e0 = np.empty(d)
    mid = np.empty(d)
    for k in range(d):
        b0[k] = corner[k] - need * u_in[k]
        e0[k] = corner[k] + need * u_out[k]
    for k in range(d):
        mid[k] = 0.5 * (b0[k] + e0[k])
    return okern.segment_clear(b0, e0, space) and okern.segment_clear(corner, mid, space)


@njit(cache=True)
def edge_cost(a, b, length_m: float, energy: float, climb_penalty: float) -> float:
    """``EdgeCost.edge(a, b, length_m)`` without threat term: ``(length + penalty * climb) * energy``."""
    cost = length_m
    if climb_penalty > 0.0:
        climb = a[2] - b[2]
        if climb > 0.0:
            cost += climb_penalty * climb
    return cost * energy
