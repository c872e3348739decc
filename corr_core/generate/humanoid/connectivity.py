"""Other connectivity: the same surface re-triangulated and its vertices shuffled, with the true map."""
from __future__ import annotations

import numpy as np


REMESH_KINDS = ("subdivided", "decimated")


def subdivide_midpoint(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """1-to-4 midpoint subdivision: V (n,3), F (m,3) -> V' (n + E,3) (the n vertices first, same ids, then
    one per edge), F' (4m,3), same orientation."""
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    edges, inverse = np.unique(E, axis=0, return_inverse=True)
    mid = len(V) + inverse.reshape(3, len(F)).T                 # (m,3): midpoint of edge (0,1), (1,2), (2,0)
    a, b, c = F.T
    ab, bc, ca = mid.T
    F2 = np.concatenate([np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return np.concatenate([V, V[edges].mean(axis=1)]), F2.astype(np.int64)


def _decimate(V: np.ndarray, F: np.ndarray, fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Quadric edge-collapse decimation (open3d) to ``fraction`` of the faces; unused vertices removed."""
    from corr_core.open3d_loader import load_open3d

    o3d = load_open3d()
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32)))
    m = m.simplify_quadric_decimation(int(len(F) * fraction))
    m.remove_unreferenced_vertices()
    return np.asarray(m.vertices, np.float64), np.asarray(m.triangles, np.int64)


def remesh(V: np.ndarray, F: np.ndarray, kind: str, *, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The same surface with another triangulation and vertex order, and the true map onto it.

    kind "subdivided": midpoint subdivision (exact: vertex i stays a vertex); "decimated": quadric decimation to
    half the faces (truth: the nearest kept vertex to each original one, i.e. exact to within an edge). The new
    vertex ids are shuffled (``np.random.default_rng(seed)``) so that no method can rely on vertex order.
    Args: V (n,3), F (m,3). Returns V2 (n2,3), F2 (m2,3), truth (n,) int: vertex of V2 that vertex i becomes.
    """
    from scipy.spatial import cKDTree

    if kind == "subdivided":
        V2, F2 = subdivide_midpoint(V, F)
        truth = np.arange(len(V))
    elif kind == "decimated":
        V2, F2 = _decimate(V, F, 0.5)
        truth = cKDTree(V2).query(V)[1]
    else:
        raise ValueError(f"remesh kind must be one of {REMESH_KINDS}, got {kind!r}")
    order = np.random.default_rng(seed).permutation(len(V2))   # new id of old vertex j: rank[j]
    rank = np.empty_like(order)
    rank[order] = np.arange(len(V2))
    return V2[order], rank[F2], rank[truth].astype(np.int64)
