"""Farthest-point sampling of point sets (deterministic)."""
from __future__ import annotations

from typing import Callable

import numpy as np


def farthest_point_samples(points: np.ndarray, k: int, start: int = 0,
                           distances: Callable[[int], np.ndarray] | None = None) -> np.ndarray:
    """Greedy farthest-point sampling.

    Each new sample is the point whose distance to the samples chosen so far is largest (ties: lowest index),
    so the result is deterministic for a given ``start``.

    Args:
        points: (n, d) float positions (used for Euclidean distances when ``distances`` is None).
        k: number of samples, 1 <= k <= n.
        start: index of the first sample.
        distances: optional callback ``distances(i) -> (n,) float``, distance from point ``i`` to every point
            (e.g. a geodesic distance from a heat-method solver). Replaces the Euclidean distance.
    Returns:
        (k,) int64 sample indices, all distinct, ``[0] == start``.
    """
    points = np.asarray(points, dtype=float)
    n = len(points)
    if not 1 <= k <= n:
        raise ValueError(f"farthest_point_samples: k={k} must be in 1..{n}")
    if not 0 <= start < n:
        raise ValueError(f"farthest_point_samples: start={start} outside 0..{n - 1}")

    def dist_from(i: int) -> np.ndarray:
        if distances is not None:
            return np.asarray(distances(i), dtype=float)
        return np.linalg.norm(points - points[i], axis=1)

    chosen = np.empty(k, dtype=np.int64)
    chosen[0] = start
    nearest = dist_from(start)
    nearest[start] = -np.inf
    for s in range(1, k):        # k is small (tens to hundreds); each step is one vectorized distance pass
        nxt = int(np.argmax(nearest))
        chosen[s] = nxt
        nearest = np.minimum(nearest, dist_from(nxt))
        nearest[chosen[: s + 1]] = -np.inf
    return chosen
