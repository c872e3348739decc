"""Farthest-point sampling of point sets (deterministic)."""
from __future__ import annotations

from typing import Callable

import numpy as np


def farthest_point_samples(points: np.ndarray, k: int, *, start: int = 0,
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

    dist_from = ((lambda i: np.asarray(distances(i), dtype=float)) if distances is not None
                 else _euclidean_distances_from(points))

    chosen = np.empty(k, dtype=np.int64)
    chosen[0] = start
    nearest = np.array(dist_from(start))             # a copy: dist_from may reuse its buffer
    nearest[start] = -np.inf
    for s in range(1, k):        # each step is one vectorized distance pass
        nxt = int(np.argmax(nearest))
        chosen[s] = nxt
        np.minimum(nearest, dist_from(nxt), out=nearest)
        nearest[chosen[: s + 1]] = -np.inf
    return chosen


def _euclidean_distances_from(points: np.ndarray) -> Callable[[int], np.ndarray]:
    """``dist_from(i) -> (n,)`` Euclidean distances from point ``i``, bit-identical to
    ``np.linalg.norm(points - points[i], axis=1)`` but per coordinate into reused buffers (no (n, d) temporaries:
    ~10x faster for 2,000 samples of 12,500 vertices). The returned array is overwritten by the next call."""
    if points.shape[1] >= 8:            # numpy sums 8 or more terms pairwise: keep its order exactly
        return lambda i: np.linalg.norm(points - points[i], axis=1)
    cols = [np.ascontiguousarray(points[:, c]) for c in range(points.shape[1])]
    d, tmp = np.empty(len(points)), np.empty(len(points))

    def dist_from(i: int) -> np.ndarray:
        d.fill(0.0)
        for col in cols:                # the same order of the squared terms as numpy's sum
            np.subtract(col, col[i], out=tmp)
            np.multiply(tmp, tmp, out=tmp)
            np.add(d, tmp, out=d)
        return np.sqrt(d, out=d)

    return dist_from
