"""Shortcutting and costing of a found path, compiled (numba) for the plain length cost.

:func:`~companion.planning.simplify.shortcut_path` followed by
:func:`~companion.planning.cost.path_cost`, for cost = energy weight x length, no K_max corner
clearance and a world the compiled segment test covers (:func:`shortcut_case`). The same greedy
rule (from each waypoint the farthest later waypoint joined by a free, cheaper edge that keeps
the heading limit at both ends), the same rounds, and the Python code's arithmetic in the same
order (``math.dist`` through :func:`~companion.planning.exact_dist.python_dist`, the section
costs summed left to right), so the path and its cost are the same to the bit. The worlds are
those of the compiled segment test (:func:`~companion.world.segments.compiled_for`: balls,
vertical cylinders, prisms).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from companion.planning.cost import EdgeCost
from companion.planning.exact_dist import python_dist
from companion.planning.search import simple_cost
from companion.planning.settings import GartSettings
from companion.world.obstacle_kernels import segment_clear, space_of
from companion.world.segments import compiled_for

__all__ = ["shortcut_case", "shortcut_and_cost"]


def shortcut_case(world, settings: GartSettings) -> bool:
    """True when :func:`shortcut_and_cost` gives the answer of the Python steps."""
    return settings.kappa_max_1_m is None and compiled_for(world) and simple_cost(EdgeCost(world, settings.cost))


def shortcut_and_cost(world, path: np.ndarray, settings: GartSettings) -> tuple[np.ndarray, float]:
    """``(path (M', d), cost)``: the path shortcut when ``settings.simplify`` says so, then costed."""
    rounds = settings.simplify.max_rounds if settings.simplify.enabled and path.shape[0] > 2 else -1
    out, cost = shortcut_polyline(
        np.ascontiguousarray(path, dtype=float),
        float(settings.cost.energy),
        math.cos(settings.max_heading_change_rad),
        rounds,
        space_of(world),
    )
    return out, cost


@njit(cache=True)
def _edges(path, idx, m, energy, u, length, terms) -> None:
    """Direction (m-1, d), length and cost term of each edge of the waypoints ``idx[:m]``."""
    d = path.shape[1]
    for k in range(m - 1):
        a, b = path[idx[k]], path[idx[k + 1]]
        length[k] = python_dist(a, b)
        for j in range(d):
            u[k, j] = (b[j] - a[j]) / length[k]
        terms[k] = length[k] * energy


@njit(cache=True)
def _dot(a, b) -> float:
    c = 0.0
    for k in range(a.shape[0]):
        c += a[k] * b[k]
    return c


@njit(cache=True)
def farthest_shortcut(path, idx, m, i, u, length, terms, energy, cos_max, space, u_new) -> int:
    """The farthest waypoint ``j > i + 1`` that a free, cheaper, heading-respecting edge joins, or -1."""
    d = path.shape[1]
    last = m - 1
    a = path[idx[i]]
    for j in range(last, i + 1, -1):
        b = path[idx[j]]
        len_new = python_dist(a, b)
        for k in range(d):
            u_new[k] = (b[k] - a[k]) / len_new
        if i > 0 and _dot(u[i - 1], u_new) < cos_max:
            continue
        new = len_new * energy
        end = j
        if j < last:
            if _dot(u_new, u[j]) < cos_max:
                continue
            end = j + 1
            new += length[j] * energy
        old = 0.0
        for k in range(i, end):
            old += terms[k]
        if not new < old - 1e-9:
            continue
        if segment_clear(a, b, space):
            return j
    return -1


@njit(cache=True)
def shortcut_polyline(path, energy, cos_max, rounds, space):
    """Shortcut ``path`` (M, d) for at most ``rounds`` rounds (-1: none) and cost it.

    Repeated waypoints (within 1e-9 m of the previous one) are dropped first, as the Python
    step does, only when shortcutting. Returns ``(path (M', d), cost)``.
    """
    m0, d = path.shape
    idx = np.arange(m0)
    m = m0
    if rounds >= 0:
        m = 0
        for k in range(m0):
            if k == 0 or python_dist(path[k], path[k - 1]) > 1e-9:
                idx[m] = k
                m += 1
    u = np.empty((max(m0, 1), d))
    length = np.empty(max(m0, 1))
    terms = np.empty(max(m0, 1))
    u_new = np.empty(d)
    for _ in range(rounds):
        changed = False
        i = 0
        _edges(path, idx, m, energy, u, length, terms)
        while i < m - 2:
            j = farthest_shortcut(path, idx, m, i, u, length, terms, energy, cos_max, space, u_new)
            if j > 0:
                gap = j - i - 1
                for k in range(j, m):
                    idx[k - gap] = idx[k]
                m -= gap
                _edges(path, idx, m, energy, u, length, terms)
                changed = True
            i += 1
        if not changed:
            break
    out = np.empty((m, d))
    for k in range(m):
        out[k] = path[idx[k]]
    total = 0.0  # path_cost: the edges' lengths x energy, left to right
    for k in range(m - 1):
        dist = python_dist(out[k], out[k + 1])
        if dist > 0.0:
            total += dist * energy
    return out, total
