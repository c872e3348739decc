"""Triangle-mesh primitives used across corr_core: areas, normals, edges, components, rotations about y.

Meshes are ``V: (n,3) float`` vertex positions and ``F: (m,3) int`` triangles (0-based, counter-clockwise =
outward). Every other module imports these instead of re-deriving them, so one formula holds everywhere.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

__all__ = [
    "face_cross", "face_areas", "face_normals", "vertex_normals", "surface_area", "surface_centroid",
    "half_edges", "edge_keys", "unique_edges", "mesh_edges", "vertex_adjacency", "vertex_components",
    "largest_component", "manifold_patches", "without_fins", "same_triangles", "rotation_about_y", "rotate_about_y",
]


def face_cross(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(m,3) un-normalized face normals (v1 - v0) x (v2 - v0): length = twice the triangle area."""
    return np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])


def face_areas(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(m,) triangle areas, units length^2."""
    return 0.5 * np.linalg.norm(face_cross(V, F), axis=1)


def face_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(m,3) float64 unit face normals (right-hand rule over the face's vertex order); degenerate faces get 0."""
    normals = face_cross(np.asarray(V, dtype=np.float64), F)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)


def vertex_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(n,3) float64 unit area-weighted vertex normals; direction from the face winding (counter-clockwise =
    outward). Vertices on no face get a zero normal."""
    V = np.asarray(V, dtype=np.float64)
    fn = face_cross(V, F)
    corners = np.asarray(F).T.ravel()           # every face's first corner, then second, then third
    N = np.column_stack([np.bincount(corners, weights=np.tile(fn[:, c], 3), minlength=len(V)) for c in range(3)])
    return N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-300)


def surface_area(V: np.ndarray, F: np.ndarray) -> float:
    """Total triangle area (length^2)."""
    return float(face_areas(V, F).sum())


def surface_centroid(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(3,) area-weighted centroid of the triangles: independent of tessellation and of rotations.
    Falls back to the vertex mean when the total area is 0."""
    area = face_areas(V, F)
    if area.sum() <= 0:
        return V.mean(axis=0)
    return (area[:, None] * V[F].mean(axis=1)).sum(axis=0) / area.sum()


def half_edges(F: np.ndarray) -> np.ndarray:
    """(3m,2) the half-edges (a,b), (b,c), (c,a) of every face, face-major."""
    return np.stack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1).reshape(-1, 2)


def edge_keys(pairs: np.ndarray) -> np.ndarray:
    """(k,) int64 key of each undirected vertex pair (k,2), equal for (a,b) and (b,a); sorting the keys sorts
    the pairs (min, max) lexicographically (a fast 1-D np.unique instead of a row-wise one)."""
    pairs = np.asarray(pairs, dtype=np.int64)
    n = int(pairs.max()) + 1 if len(pairs) else 1
    return np.minimum(pairs[:, 0], pairs[:, 1]) * n + np.maximum(pairs[:, 0], pairs[:, 1])


def unique_edges(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges (e,2) int, each row sorted and rows in lexicographic order, and the number of
    faces using each edge (e,) int (1 = boundary, 2 = interior, > 2 = non-manifold)."""
    half = half_edges(np.asarray(F))
    _, first, counts = np.unique(edge_keys(half), return_index=True, return_counts=True)
    return np.sort(half[first], axis=1), counts


def mesh_edges(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Number the edges of a triangle mesh by first appearance (the course's flattened-mesh numbering).

    Walk the faces in order, and in each face its edges (a,b), (b,c), (c,a); an edge gets the next id the first
    time it is seen.
    Returns:
        edges: (n_edges, 2) int, vertex pair of each edge in the order first seen.
        face_edges: (m, 3) int, edge ids of each face's (a,b), (b,c), (c,a).
    """
    F = np.asarray(F, dtype=np.int64)
    half = half_edges(F)
    _, first, inverse = np.unique(edge_keys(half), return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")           # unique keys in order of first appearance
    rank = np.empty(len(first), dtype=np.int64)
    rank[order] = np.arange(len(first))
    return half[first[order]], rank[inverse.ravel()].reshape(-1, 3)


def vertex_adjacency(F: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """(n,n) symmetric 0/1 float64 vertex adjacency of the triangles F: (m,3)."""
    i = np.concatenate([F[:, 0], F[:, 1], F[:, 2]])
    j = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    A = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n_vertices, n_vertices)).tocsr()
    return ((A + A.T) > 0).astype(np.float64).tocsr()


def vertex_components(n_vertices: int, F: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected components of the vertices joined by faces: (count, labels (n,) int).

    Labels are numbered by each component's lowest vertex id; vertices used by no face form their own singleton
    components.
    """
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]]])
    A = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n_vertices, n_vertices))
    return connected_components(A, directed=False)


def largest_component(V: np.ndarray, F: np.ndarray, by: str = "area") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keep one face-connected component: the one with the largest surface area (``by="area"``) or the most
    vertices (``by="vertices"``); ties go to the component with the lowest vertex id.

    Returns:
        V2: (n2,3); F2: (m2,3) re-indexed; kept: (n2,) int original ids of the kept vertices, increasing
        (V2 = V[kept]). Vertex ids change, so "vertex i matches vertex i" ground truth must be mapped through
        ``kept``.
    """
    _, labels = vertex_components(len(V), F)
    face_label = labels[F[:, 0]]
    if by == "area":
        size = np.bincount(face_label, weights=face_areas(V, F), minlength=labels.max() + 1)
    elif by == "vertices":
        size = np.bincount(labels[np.unique(F)], minlength=labels.max() + 1)
    else:
        raise ValueError(f"largest_component: by must be 'area' or 'vertices', got {by!r}")
    F_keep = F[face_label == int(np.argmax(size))]
    kept = np.unique(F_keep)
    remap = np.full(len(V), -1, dtype=np.int64)
    remap[kept] = np.arange(len(kept))
    return V[kept], remap[F_keep], kept


def manifold_patches(F: np.ndarray) -> tuple[int, np.ndarray]:
    """Faces joined only across edges that exactly two faces share: (count, labels (m,) int, one per face).

    On an edge-manifold mesh the patches are its connected components. A fin (faces hanging on an edge that
    three or more faces share, e.g. a stray triangle standing on a surface) is cut off there and becomes a patch
    of its own; so does anything attached to the rest only along such edges.
    """
    F = np.asarray(F, dtype=np.int64)
    _, edge_of_half, counts = np.unique(edge_keys(half_edges(F)), return_inverse=True, return_counts=True)
    face_of_half = np.repeat(np.arange(len(F)), 3)
    manifold = counts[edge_of_half] == 2
    order = np.argsort(edge_of_half[manifold], kind="stable")      # the two half-edges of each manifold edge
    pairs = face_of_half[manifold][order].reshape(-1, 2)
    A = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(F), len(F)))
    return connected_components(A, directed=False)


def without_fins(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """The faces of the largest ``manifold_patches`` patch by area (ties: the lowest label), or F itself (the same
    object) when no edge has more than two faces. V: (n,3) float; F: (m,3) int. Returns (m2,3) int, rows of F."""
    _, counts = unique_edges(F)
    if not (counts > 2).any():
        return F
    n_patches, labels = manifold_patches(F)
    if n_patches < 2:
        return F
    area = np.bincount(labels, weights=face_areas(V, F), minlength=n_patches)
    return F[labels == int(np.argmax(area))]


def _canonical_triangles(F: np.ndarray) -> np.ndarray:
    """(m,3) int64: each triangle's vertex ids sorted, the rows sorted (the triangle set, order-free)."""
    A = np.sort(np.asarray(F, dtype=np.int64).reshape(-1, 3), axis=1)
    return A[np.lexsort(A.T[::-1])]


def same_triangles(F_a: np.ndarray, F_b: np.ndarray) -> bool:
    """True when F_a: (m,3) and F_b: (m,3) hold the same triangles as vertex sets, in any order."""
    if np.shape(F_a) != np.shape(F_b):
        return False
    return bool(np.array_equal(_canonical_triangles(F_a), _canonical_triangles(F_b)))


def triangles_key(F: np.ndarray) -> str:
    """A short text equal for two face arrays exactly when ``same_triangles`` holds (sha256 of the sorted
    triangle set): lets a per-mesh result say which numbering it is in without keeping its faces."""
    import hashlib

    return hashlib.sha256(np.ascontiguousarray(_canonical_triangles(F)).tobytes()).hexdigest()[:32]


def rotation_about_y(angle_rad: float) -> np.ndarray:
    """(3,3) right-handed rotation by ``angle_rad`` about +y: x' = cos a x + sin a z, z' = -sin a x + cos a z
    (+angle turns +x toward -z)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotate_about_y(V: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rotate points V: (n,3) about the y axis through the origin by ``angle_rad`` (see ``rotation_about_y``).
    Returns (n,3), same dtype as ``V`` for float input (float64 otherwise)."""
    V = np.asarray(V)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError(f"V must be (n, 3), got shape {V.shape}")
    out_dtype = V.dtype if np.issubdtype(V.dtype, np.floating) else np.float64
    return (V @ rotation_about_y(angle_rad).T).astype(out_dtype, copy=False)
