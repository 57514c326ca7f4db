"""GART's whole iteration compiled (numba): sample, attract, steer, choose parent, insert, rewire, goal.

For the common case (the length and climb cost, a world of discs/spheres, vertical cylinders and
prisms, K_max corner clearance or not) :func:`grow_batch` runs many iterations of
:meth:`~companion.planning.search.GartSearch.iterate` in one call, with the tree in preallocated
arrays (:class:`~companion.planning.compiled_search.CompiledGart` owns them and grows them by
doubling between calls). Every step does the Python code's floating-point operations in the
same order (``math.dist`` through :func:`~companion.planning.exact_dist.python_dist`, no
fast-math), consumes the uniform numbers in the same order and takes the same decisions, so a
seed gives the same tree and path as the Python iteration.

The tree arrays, rows indexed by node id (n nodes, capacity ``cap``, dimension d):
``coords`` (cap, d), ``keys`` (cap,) bucket keys, ``active`` (cap,), ``parent`` (cap,),
``cost`` (cap,) cost-to-come, ``u`` (cap, d) incoming unit direction, ``has_u`` (cap,),
``length`` (cap,) incoming edge length, ``edge`` (cap,) incoming edge cost, and the children as
doubly linked lists ``first_child``, ``next_sib``, ``prev_sib`` (cap,). Goal links, in the order
they were made: ``link_of`` (cap,) node -> link or -1, ``gl_node``, ``gl_e`` (edge cost),
``gl_u`` (cap, d), ``gl_len``. ``counters`` (int64): node count, iterations, best node, link
count, position in the block of uniform numbers; ``best`` (1,): best cost. (numba's cache
notices edits of a kernel's own file only: after editing a kernel this one calls, clear
``__pycache__``.)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from companion.planning.corner_kernel import corner_clear, corner_fits, edge_cost
from companion.planning.exact_dist import python_dist
from companion.planning.guidance import attract_to_balls
from companion.planning.node_arrays import append_kernel, nearest_kernel
from companion.planning.parent_choice import extend
from companion.world import obstacle_kernels as okern

__all__ = [
    "grow_batch",
    "BATCH_DONE",
    "IMPROVED",
    "NEED_RANDOM",
    "NEW_NODE",
    "GART",
    "MGART_LINKS",
    "MGART_NODES",
    "N_NODES",
    "ITERATIONS",
    "BEST_NODE",
    "N_LINKS",
    "RANDOM_POS",
]

BATCH_DONE, IMPROVED, NEED_RANDOM, NEW_NODE = 0, 1, 2, 3  # why grow_batch returned
GART, MGART_LINKS, MGART_NODES = 0, 1, 2  # modes: stop at a lower best cost, at a goal link, at every node
N_NODES, ITERATIONS, BEST_NODE, N_LINKS, RANDOM_POS = 0, 1, 2, 3, 4  # counters
_INFORMED_TRIES = 20


@njit(cache=True)
def draw_sample(rand, pos, x, goal, lo, hi, span, goal_bias, c_best_m, informed, has_ellipse, c_min, basis, centre):
    """Step 1 (:meth:`~companion.planning.sampling.Sampler.sample`) into ``x`` (d,).

    Uniform numbers are read from ``rand`` at ``pos``. Returns ``(pos after, is_goal)``; pos -1
    when the block ran out (the caller draws more and repeats the whole sample).
    """
    m = rand.shape[0]
    d = x.shape[0]
    if pos >= m:
        return -1, False
    pos += 1
    if rand[pos - 1] < goal_bias:
        x[:] = goal
        return pos, True
    if informed and c_best_m < np.inf and has_ellipse and c_best_m > c_min:
        r_major = 0.5 * c_best_m
        r_minor = 0.5 * math.sqrt(c_best_m * c_best_m - c_min * c_min)
        ball = np.empty(d)
        for _ in range(_INFORMED_TRIES):
            while True:  # a uniform point of the unit ball, by rejection
                if pos + d > m:
                    return -1, False
                s2 = 0.0
                for k in range(d):
                    ball[k] = 2.0 * rand[pos] - 1.0
                    pos += 1
                for k in range(d):
                    s2 += ball[k] * ball[k]
                if s2 <= 1.0:
                    break
            x[:] = centre
            for k in range(basis.shape[0]):
                scale = (r_major if k == 0 else r_minor) * ball[k]
                for j in range(d):
                    x[j] += scale * basis[k, j]
            inside = True
            for j in range(d):
                if not (lo[j] <= x[j] and x[j] <= hi[j]):
                    inside = False
            if inside:
                return pos, False
    if pos + d > m:
        return -1, False
    for k in range(d):
        x[k] = lo[k] + rand[pos] * span[k]
        pos += 1
    return pos, False


@njit(cache=True)
def steer(x_from, x_to, step_m: float, x_new) -> bool:
    """Step 3: ``x_new`` at most ``step_m`` from ``x_from`` towards ``x_to``; False when they coincide."""
    dist = python_dist(x_from, x_to)
    if dist < 1e-9:
        return False
    if dist <= step_m:
        x_new[:] = x_to
        return True
    f = step_m / dist
    for k in range(x_new.shape[0]):
        x_new[k] = x_from[k] + f * (x_to[k] - x_from[k])
    return True


@njit(cache=True)
def rewire_radius(n: int, gamma: float, r_max: float, d: int) -> float:
    """The shrinking RRT* radius for ``n`` nodes (:meth:`GartSearch.radius`)."""
    if n < 2:
        return r_max
    r = gamma * (math.log(n) / n) ** (1.0 / d)
    return r if r < r_max else r_max


@njit(cache=True)
def _link_child(first_child, next_sib, prev_sib, parent: int, child: int) -> None:
    head = first_child[parent]
    next_sib[child] = head
    prev_sib[child] = -1
    if head >= 0:
        prev_sib[head] = child
    first_child[parent] = child


@njit(cache=True)
def _unlink_child(first_child, next_sib, prev_sib, parent: int, child: int) -> None:
    before, after = prev_sib[child], next_sib[child]
    if before >= 0:
        next_sib[before] = after
    else:
        first_child[parent] = after
    if after >= 0:
        prev_sib[after] = before


@njit(cache=True)
def _children_fit(tree, i: int, uu, dist: float, rule, corner, space) -> bool:
    """The corners at node ``i`` towards each of its children, entered along ``uu`` (``dist`` m).

    ``corner`` None: :meth:`CornerRule.ok` without the corner point; else with it.
    """
    u, length, first_child, next_sib = tree[5], tree[7], tree[9], tree[10]
    ch = first_child[i]
    while ch >= 0:
        if corner is None:
            if not corner_fits(uu, dist, u[ch], length[ch], rule):
                return False
        elif not corner_clear(uu, dist, u[ch], length[ch], corner, rule, space):
            return False
        ch = next_sib[ch]
    return True


@njit(cache=True)
def _rewire_allowed(tree, link_of, gl_u, gl_len, node: int, i: int, uu, dist: float, rule, space) -> bool:
    """The tests of :meth:`GartSearch.rewire` after the cost test: corners, edge, K_max's corners."""
    coords, u, length = tree[0], tree[5], tree[7]
    link = link_of[i]
    if not corner_fits(u[node], length[node], uu, dist, rule) or not _children_fit(
        tree, i, uu, dist, rule, None, space
    ):
        return False
    if link >= 0 and not corner_fits(uu, dist, gl_u[link], gl_len[link], rule):
        return False
    if not okern.segment_clear(coords[node], coords[i], space):
        return False
    if rule[1] == 0.0:
        return True
    return (
        corner_clear(u[node], length[node], uu, dist, coords[node], rule, space)
        and _children_fit(tree, i, uu, dist, rule, coords[i], space)
        and (link < 0 or corner_clear(uu, dist, gl_u[link], gl_len[link], coords[i], rule, space))
    )


@njit(cache=True)
def rewire(tree, links, node: int, ids, dists, energy: float, climb_penalty: float, rule, space, stack) -> None:
    """Step 5 (:meth:`GartSearch.rewire` for the length and climb cost): re-parent cheaper neighbours."""
    coords, keys, active, parent, cost, u, has_u, length, edge, first_child, next_sib, prev_sib = tree
    link_of, gl_u, gl_len = links[0], links[3], links[4]
    d = coords.shape[1]
    x_new = coords[node]
    c_new = cost[node]
    skip = parent[node]
    uu = np.empty(d)
    for a in range(ids.shape[0]):
        i = ids[a]
        dist = dists[a]
        if c_new + dist * energy >= cost[i]:
            continue
        if i == 0 or i == skip or dist < 1e-9:
            continue
        for k in range(d):
            uu[k] = (coords[i, k] - x_new[k]) / dist
        e = edge_cost(x_new, coords[i], dist, energy, climb_penalty)
        c = c_new + e
        if c >= cost[i] - 1e-9 or not _rewire_allowed(tree, link_of, gl_u, gl_len, node, i, uu, dist, rule, space):
            continue
        _unlink_child(first_child, next_sib, prev_sib, parent[i], i)
        parent[i] = node
        _link_child(first_child, next_sib, prev_sib, node, i)
        edge[i], length[i], cost[i] = e, dist, c
        u[i, :] = uu
        top = 0  # propagate the new cost to the descendants
        stack[top] = i
        top += 1
        while top > 0:
            top -= 1
            m = stack[top]
            ch = first_child[m]
            while ch >= 0:
                cost[ch] = cost[m] + edge[ch]
                stack[top] = ch
                top += 1
                ch = next_sib[ch]


@njit(cache=True)
def connect_goal(
    tree, links, counters, node: int, goal, goal_radius: float, energy: float, climb_penalty: float, rule, space
) -> None:
    """Step 6 (:meth:`GartSearch.connect_goal`): a straight edge from ``node`` to the goal, recorded."""
    coords, u, length = tree[0], tree[5], tree[7]
    link_of, gl_node, gl_e, gl_u, gl_len = links
    dist = python_dist(coords[node], goal)
    if dist > goal_radius:
        return
    k = counters[N_LINKS]
    if dist < 1e-9:
        gl_u[k, :] = u[node]
        e = dist = 0.0
    else:
        for j in range(coords.shape[1]):
            gl_u[k, j] = (goal[j] - coords[node, j]) / dist
        if not corner_fits(u[node], length[node], gl_u[k], dist, rule):
            return
        if not okern.segment_clear(coords[node], goal, space):
            return
        if rule[1] > 0.0 and not corner_clear(u[node], length[node], gl_u[k], dist, coords[node], rule, space):
            return
        e = edge_cost(coords[node], goal, dist, energy, climb_penalty)
    gl_node[k], gl_e[k], gl_len[k] = node, e, dist
    link_of[node] = k
    counters[N_LINKS] = k + 1


@njit(cache=True)
def update_best(cost, links, counters, best) -> bool:
    """:meth:`GartSearch.update_best` over the goal links in order; True when the best cost went down."""
    gl_node, gl_e = links[1], links[2]
    best_node, best_cost = counters[BEST_NODE], best[0]
    link_best = -1
    for k in range(counters[N_LINKS]):
        c = cost[gl_node[k]] + gl_e[k]
        if c < best_cost - 1e-12:
            best_node, best_cost, link_best = gl_node[k], c, k
    if best_node >= 0:
        if link_best < 0:
            link_best = links[0][best_node]
        best_cost = cost[best_node] + gl_e[link_best]
    improved = best_cost < best[0] - 1e-12
    counters[BEST_NODE] = best_node
    best[0] = best_cost
    return improved


@njit(cache=True)
def grow_batch(tree, links, counters, best, rand, problem, params, max_iterations: int, mode: int) -> int:
    """Up to ``max_iterations`` GART iterations; returns BATCH_DONE, IMPROVED, NEW_NODE or NEED_RANDOM.

    Parameters
    ----------
    tree, links : tuples of arrays
        See the module docstring; capacity for ``max_iterations`` more nodes is required.
    counters : (5,) int64
        N_NODES, ITERATIONS, BEST_NODE, N_LINKS, RANDOM_POS (updated).
    best : (1,) float
        Best goal cost so far (updated).
    rand : (m,) float
        Uniform numbers of the planner's stream; reading starts at ``counters[RANDOM_POS]``.
    problem : tuple
        goal (d,), bounds lo, hi, span (d,), the world's obstacles (``space``,
        :func:`~companion.world.obstacle_kernels.space_of`), guidance rows (N, d + 2), informed
        basis (d, d) and centre (d,), bucket 1/edge, bucket shape (d,), the corner rule
        (:func:`~companion.planning.corner_kernel.rule_of`).
    params : tuple
        goal_bias, step, goal radius, r_max, gamma, energy, climb penalty, c_min, obstacle gain,
        repel offset, goal gain, max guidance, influence (floats), guided, informed, has_ellipse
        (bools).

    max_iterations, mode : int
        ``mode`` GART: the best goal cost is kept up to date and the call returns IMPROVED right
        after an iteration that lowered it. MGART_LINKS: no best cost (M-GART never asks for one,
        so sampling stays uniform); returns NEW_NODE right after a node got a goal link (the
        caller removes the link). MGART_NODES: returns NEW_NODE after every new node.

    Returns NEED_RANDOM (that iteration not started) when ``rand`` ran out.
    """
    coords, keys, active, parent, cost, u, has_u, length, edge, first_child, next_sib, prev_sib = tree
    goal, lo, hi, span, space, ball_rows, basis, centre, inv_cell, shape, rule = problem
    (
        goal_bias,
        step,
        goal_radius,
        r_max,
        gamma,
        energy,
        climb,
        c_min,
        gain,
        repel,
        goal_gain,
        max_guidance,
        influence,
        guided,
        informed,
        has_ellipse,
    ) = params
    d = coords.shape[1]
    x = np.empty(d)
    x_new = np.empty(d)
    stack = np.empty(coords.shape[0], dtype=np.int64)
    for _ in range(max_iterations):
        pos, is_goal = draw_sample(
            rand,
            counters[RANDOM_POS],
            x,
            goal,
            lo,
            hi,
            span,
            goal_bias,
            best[0] / energy,
            informed,
            has_ellipse,
            c_min,
            basis,
            centre,
        )
        if pos < 0:
            return NEED_RANDOM
        counters[RANDOM_POS] = pos
        counters[ITERATIONS] += 1
        x_rand = x
        if guided and not is_goal:
            x_rand = attract_to_balls(
                x, goal, lo, hi, ball_rows, space, influence, gain, repel, goal_gain, max_guidance
            )
        n = counters[N_NODES]
        near = nearest_kernel(coords, active, n, x_rand)
        if near < 0 or not steer(coords[near], x_rand, step, x_new):
            continue
        near_dist = python_dist(coords[near], x_new)
        _, chosen, ids, dists = extend(
            x_new,
            near,
            near_dist,
            rewire_radius(n, gamma, r_max, d),
            coords,
            keys,
            active,
            n,
            cost,
            u,
            has_u,
            length,
            energy,
            climb,
            rule,
            space,
        )
        if chosen < 0:
            continue
        p, dist = ids[chosen], dists[chosen]  # step 4 chose the parent: insert the node
        append_kernel(coords, keys, active, n, x_new, lo, inv_cell, shape)
        for k in range(d):
            u[n, k] = (x_new[k] - coords[p, k]) / dist
        e = edge_cost(coords[p], x_new, dist, energy, climb)
        parent[n], cost[n], edge[n], length[n], has_u[n] = p, cost[p] + e, e, dist, True
        first_child[n] = -1
        _link_child(first_child, next_sib, prev_sib, p, n)
        links[0][n] = -1
        counters[N_NODES] = n + 1
        rewire(tree, links, n, ids, dists, energy, climb, rule, space, stack)
        connect_goal(tree, links, counters, n, goal, goal_radius, energy, climb, rule, space)
        if mode == GART:
            if counters[N_LINKS] > 0 and update_best(cost, links, counters, best):
                return IMPROVED
        elif mode == MGART_NODES or counters[N_LINKS] > 0:
            return NEW_NODE
    return BATCH_DONE
