"""Nearest target vertex whose normal agrees: the closest-point query every refinement step shares."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def nearest_compatible(tree: cKDTree, normals_t: np.ndarray, P: np.ndarray, normals_p: np.ndarray, *,
                       min_cos: float, k: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Nearest target vertex to each point P (q,3) among its ``k`` nearest whose normal (n_t,3) makes a cosine
    > ``min_cos`` with the point's normal (q,3): (ids (q,) int, distances (q,) float, inf when none qualifies).

    ``tree`` is a k-d tree of the target vertices (n_t,3). The normal test rejects a touching body part (it faces
    the other way) and the other side of a thin part."""
    d, c = tree.query(P, k=min(k, len(normals_t)))
    d, c = d.reshape(len(P), -1), c.reshape(len(P), -1)
    d = np.where(np.einsum("ij,ikj->ik", normals_p, normals_t[c]) > min_cos, d, np.inf)
    best = np.argmin(d, axis=1)
    rows = np.arange(len(P))
    return c[rows, best], d[rows, best]
