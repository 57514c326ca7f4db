"""M-GART: several distinct paths from one GART tree by *Extending Forbidden* (paper 3.3, Fig. 7).

The GART tree grows as usual. Whenever a branch reaches the goal, the path is shortcut, and
kept if it is *distinct* from every path kept so far (if only the unshortcut branch is
distinct, that one is kept); in every case the branch's nodes are then
forbidden (``forbid_branch``): removed from the nearest-neighbour structure, so they are neither
extended nor rewired any more, except those within ``keep_near_root_m`` of the start (and of the
goal), which stay available so new branches can leave the start and still reach the goal. With
``forbid_tube_m > 0`` the nodes within that distance of the branch are forbidden too, which
steers the next branches away from the same corridor (a speed-up over the paper, where only the
branch itself is forbidden; ``forbid_tube_m = 0`` gives the paper's rule). The waypoints of each
path kept within ``portal_zone_m`` of the goal become goal portals
(:mod:`companion.planning.portals`): a later branch may end by joining one, so a goal reached
only through a pocket is not re-entered by chance for every path (``portal_zone_m = 0``: the
paper's rule). The tree keeps growing until ``k`` paths exist or the budget is spent. The
threat manager uses the paths as pre-planned alternatives.

Distinctness measure: the discrete Hausdorff distance between the two paths, each resampled every
``separation_sample_m``, must be at least ``min_separation_m``. Paths are returned sorted by cost
(paper eq. 3).
"""

from __future__ import annotations

import logging
import math
import time
from typing import Protocol, TypeVar

import numpy as np

from companion.errors import PlanningError
from companion.planning.compiled_mgart import CompiledMgartSearch
from companion.planning.compiled_search import compiled_case
from companion.planning.cost import path_cost, path_length_m
from companion.planning.gart import finish_path, warm
from companion.planning.hausdorff_kernel import UNSURE, resample_points, separated_kernel
from companion.planning.portals import GoalPortals
from companion.planning.problem import validate_problem
from companion.planning.result import PlanResult, Status
from companion.planning.search import GartSearch
from companion.planning.settings import MgartSettings

__all__ = ["mgart", "hausdorff_m", "hausdorff_of_points", "resample_path", "separated"]

log = logging.getLogger(__name__)


def resample_path(path: np.ndarray, step_m: float) -> np.ndarray:
    """Points along ``path`` (M, d) every ``step_m`` or closer, ends included: (K, d).

    Each edge gets ``n = max(1, ceil(|b - a| / step_m))`` points ``a + (i / n) (b - a)``,
    i = 1 .. n (|b - a| as ``numpy.linalg.norm`` computes it: the square root of the dot product).
    """
    path = np.ascontiguousarray(path, dtype=float)
    counts = [max(1, int(math.ceil(math.sqrt(e.dot(e)) / step_m))) for e in np.diff(path, axis=0)]
    return resample_points(path, np.array(counts, dtype=np.int64))


def hausdorff_m(path_a: np.ndarray, path_b: np.ndarray, step_m: float = 1.0) -> float:
    """Discrete Hausdorff distance (m) between two polylines resampled every ``step_m``."""
    return hausdorff_of_points(resample_path(path_a, step_m), resample_path(path_b, step_m))


def hausdorff_of_points(a: np.ndarray, b: np.ndarray) -> float:
    """Discrete Hausdorff distance (m) between the point sets ``a`` (K, d) and ``b`` (L, d)."""
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return float(max(d.min(axis=1).max(), d.min(axis=0).max()))


def separated(a: np.ndarray, b: np.ndarray, threshold_m: float) -> bool:
    """``hausdorff_of_points(a, b) >= threshold_m`` for resampled paths; compiled where the answer is sure."""
    answer = separated_kernel(a, b, float(threshold_m))
    if answer == UNSURE:
        return hausdorff_of_points(a, b) >= threshold_m
    return bool(answer)


_T_co = TypeVar("_T_co", covariant=True)


class _Indexed(Protocol[_T_co]):
    def __getitem__(self, i: int, /) -> _T_co: ...


class _Flags(Protocol):
    def __getitem__(self, i: int, /) -> bool: ...

    def __setitem__(self, i: int, value: bool, /) -> None: ...


class _Neighbours(Protocol):
    def within(self, p: tuple, radius_m: float) -> list[tuple[int, float]]: ...

    def remove(self, node: int) -> None: ...


class BranchSearch(Protocol):
    """What :func:`forbid_branch` reads and writes: a :class:`GartSearch` (lists, a NodeGrid) or a
    :class:`CompiledMgartSearch` (views of its arrays under the same names)."""

    @property
    def start(self) -> tuple: ...

    @property
    def goal(self) -> tuple: ...

    @property
    def pts(self) -> _Indexed[tuple]: ...

    @property
    def forbidden(self) -> _Flags: ...

    @property
    def nn(self) -> _Neighbours: ...

    def branch(self, node: int) -> list[int]: ...


def forbid_branch(search: BranchSearch, node: int, keep_near_root_m: float, tube_m: float) -> int:
    """Forbid extension of the branch root -> ``node`` and of the nodes within ``tube_m`` of it.

    Nodes within ``keep_near_root_m`` of the start or the goal stay extendable. Returns the
    number of nodes forbidden.
    """
    count = 0
    pts, start, goal = search.pts, search.start, search.goal
    for b in search.branch(node):
        around = [(b, 0.0)] + (search.nn.within(pts[b], tube_m) if tube_m > 0 else [])
        for i, _ in around:
            if i == 0 or search.forbidden[i]:
                continue
            if math.dist(pts[i], start) <= keep_near_root_m or (
                i != node and math.dist(pts[i], goal) <= keep_near_root_m
            ):
                continue
            search.forbidden[i] = True
            search.nn.remove(i)
            count += 1
    return count


def mgart(
    world,
    start,
    goal,
    k: int,
    *,
    rng: np.random.Generator,
    max_time_s: float | None = None,
    settings: MgartSettings | None = None,
    max_iterations: int | None = None,
) -> list[PlanResult]:
    """Up to ``k`` distinct collision-free paths from ``start`` to ``goal``, cheapest first.

    Parameters
    ----------
    world : World
    start, goal : (d,) array_like
    k : int
        Number of paths wanted, >= 1.
    rng : numpy.random.Generator
    max_time_s : float, optional
        Wall-clock budget (default ``settings.time_budget_s``, unless ``max_iterations`` is given).
    settings : MgartSettings, optional
    max_iterations : int, optional
        Iteration budget (a deterministic search: the same paths whatever the machine's speed).

    Returns
    -------
    list of PlanResult
        The paths found (status 'exact'), sorted by cost; fewer than ``k`` when the budget ran
        out. When none was found: one result with status 'timeout', 'invalid_start' or
        'invalid_goal'. All results share the final tree (with ``forbidden`` nodes marked).

    Notes
    -----
    The first call in a process compiles the planners' kernels before the budget's clock
    starts (:func:`companion.planning.gart.warm`).
    """
    warm()
    t0 = time.perf_counter()
    settings = settings or MgartSettings()
    if not isinstance(settings, MgartSettings):
        raise PlanningError(f"settings: expected MgartSettings, got {type(settings).__name__}")
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise PlanningError(f"k: must be a positive integer, got {k!r}")
    start_t, goal_t = validate_problem(world, start, goal, rng, max_time_s, max_iterations)
    gs = settings.gart
    if not world.point_free(start_t) or not world.point_free(goal_t):
        status: Status = "invalid_start" if not world.point_free(start_t) else "invalid_goal"
        return [
            PlanResult(
                status=status,
                path=None,
                cost=math.inf,
                length_m=math.inf,
                iterations=0,
                elapsed_s=time.perf_counter() - t0,
                time_to_first_s=None,
                tree=None,
            )
        ]
    if max_time_s is None and max_iterations is None:
        max_time_s = settings.time_budget_s
    deadline = t0 + max_time_s if max_time_s is not None else math.inf
    iter_limit = max_iterations if max_iterations is not None else math.inf
    compiled = compiled_case(world, gs)  # the whole iteration compiled (numba), the tree in arrays
    search = (CompiledMgartSearch if compiled else GartSearch)(world, start_t, goal_t, gs, rng)
    portals = GoalPortals(search, settings.portal_zone_m)
    found: list[tuple[np.ndarray, float, float, float]] = []  # path, cost, length, t_found
    clock = time.perf_counter

    kept_points: list[np.ndarray] = []  # the paths found, resampled for the distinctness test

    def consider(raw: np.ndarray) -> None:
        # the shortcut path if it is distinct; else the branch as grown (shortcutting can pull
        # a new branch back onto an earlier path, e.g. onto a free straight line)
        for path, cost, length in (finish_path(world, raw, gs), raw_costed(raw)):
            points = resample_path(path, settings.separation_sample_m)
            if all(separated(points, other, settings.min_separation_m) for other in kept_points):
                kept_points.append(points)
                found.append((path, cost, length, clock() - t0))
                log.debug("mgart: path %d after %d iterations, cost %.2f", len(found), search.iterations, cost)
                return

    def raw_costed(raw: np.ndarray) -> tuple[np.ndarray, float, float]:
        return raw, path_cost(world, raw, gs.cost), path_length_m(raw)

    if world.segment_free(start_t, goal_t):
        consider(np.array([start_t, goal_t]))
    while len(found) < k and clock() < deadline and search.iterations < iter_limit:
        node = (
            search.iterate(bool(portals.items), iter_limit - search.iterations)
            if isinstance(search, CompiledMgartSearch)
            else search.iterate()
        )  # i.e. if compiled
        if node < 0:
            continue
        raw = search.path_to_goal(node) if node in search.goal_links else portals.join(node)
        if raw is None:
            continue
        kept = len(found)
        consider(raw)
        if len(found) > kept:
            portals.add_path(found[-1][0])
        forbid_branch(search, node, settings.keep_near_root_m, settings.forbid_tube_m)
        search.goal_links.pop(node, None)
    tree = search.tree()
    elapsed = clock() - t0
    if not found:
        return [
            PlanResult(
                status="timeout",
                path=None,
                cost=math.inf,
                length_m=math.inf,
                iterations=search.iterations,
                elapsed_s=elapsed,
                time_to_first_s=None,
                tree=tree,
            )
        ]
    found.sort(key=lambda f: f[1])
    return [
        PlanResult(
            status="exact",
            path=p,
            cost=c,
            length_m=L,
            iterations=search.iterations,
            elapsed_s=elapsed,
            time_to_first_s=t,
            tree=tree,
        )
        for p, c, L, t in found
    ]
