"""Exact clearance of many points to many balls, through a KD-tree of the centres (pure numpy/scipy)."""

from __future__ import annotations

import numpy as np

__all__ = ["ball_clearance_kdtree"]


def ball_clearance_kdtree(pts: np.ndarray, centers: np.ndarray, radii: np.ndarray, memo: dict) -> np.ndarray:
    """Exact min over balls of ``|p - c| - r``: ``pts`` (K, d), ``centers`` (N, d), ``radii`` (N,)
    -> (K,). The KD-tree is kept in ``memo["kdtree"]`` (built once per set of balls).

    The k nearest centres give a candidate minimum; a ball further than the k-th centre can
    only beat it when ``|p - c_k| - r_max`` is below it, and those points fall back to a full
    scan, so the result is exact.
    """
    tree = memo.get("kdtree")
    if tree is None:
        from scipy.spatial import cKDTree

        tree = cKDTree(centers)
        memo["kdtree"] = tree
    k = min(16, len(radii))
    dist, idx = tree.query(pts, k=k)
    dist = dist.reshape(len(pts), k)
    idx = idx.reshape(len(pts), k)
    best = (dist - radii[idx]).min(axis=1)
    unsure = dist[:, -1] - radii.max() < best
    if k < len(radii) and np.any(unsure):
        sub = pts[unsure]
        full = np.linalg.norm(sub[:, None, :] - centers[None, :, :], axis=2) - radii[None, :]
        best[unsure] = full.min(axis=1)
    return best
