"""Checks that a mesh is fit for intrinsic (Laplacian / geodesic) correspondence.

Errors (``MeshError``): non-manifold edges, degenerate faces, several connected components (unless
``allow_components``; repair with ``largest_component``), different connectivity where it must be equal.
Warnings (returned strings): boundary edges, vertices used by no face.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from corr_core.geometry.mesh_io import MeshError, check_mesh


def _edges(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges (e,2) of the triangles and how many faces use each (e,)."""
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    return np.unique(E, axis=0, return_counts=True)


def face_areas(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(m,) triangle areas, units length^2."""
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)


def vertex_components(n_vertices: int, F: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected components of the vertices joined by faces: (count, labels (n,) int).

    Vertices used by no face form their own singleton components.
    """
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]]])
    A = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n_vertices, n_vertices))
    return connected_components(A, directed=False)


def largest_component(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keep the face-connected component with the largest surface area (a repair for stray pieces).

    Returns:
        V2: (n2,3); F2: (m2,3) re-indexed; kept: (n2,) int original ids of the kept vertices (V2 = V[kept]).
        Note: vertex ids change, so "vertex i matches vertex i" ground truth must be mapped through ``kept``.
    """
    _, labels = vertex_components(len(V), F)
    face_label = labels[F[:, 0]]
    area = np.bincount(face_label, weights=face_areas(V, F), minlength=labels.max() + 1)
    best = int(np.argmax(area))
    F_keep = F[face_label == best]
    kept = np.unique(F_keep)
    remap = np.full(len(V), -1, dtype=np.int64)
    remap[kept] = np.arange(len(kept))
    return V[kept], remap[F_keep], kept


def check_correspondence_mesh(V: np.ndarray, F: np.ndarray, name: str = "mesh",
                              allow_components: bool = False, area_tol: float = 1e-12) -> list[str]:
    """Validate a mesh for spectral / geodesic correspondence.

    Args:
        V: (n,3) float; F: (m,3) int; name: used in messages (e.g. the file name).
        allow_components: if True, several connected components give a warning instead of an error.
        area_tol: a face is degenerate when its area <= area_tol * (bounding-box diagonal)^2 or it repeats a
            vertex.
    Returns:
        list of warning strings (boundary, unreferenced vertices, components when allowed).
    Raises:
        MeshError: basic problems (see ``meshio.check_mesh``), non-manifold edges, degenerate faces,
        several connected components.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    check_mesh(V, F, name=name)
    warns: list[str] = []

    repeated = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    diag2 = float(np.sum((V.max(0) - V.min(0)) ** 2))
    degenerate = repeated | (face_areas(V, F) <= area_tol * max(diag2, np.finfo(float).tiny))
    if degenerate.any():
        ids = np.flatnonzero(degenerate)
        raise MeshError(f"{name}: {len(ids)} degenerate (zero-area) face(s), first: face {int(ids[0])}; "
                        "the cotan Laplacian is undefined there — remove or repair them")

    E, count = _edges(F)
    if np.any(count > 2):
        bad = E[np.flatnonzero(count > 2)[0]]
        raise MeshError(f"{name}: {int(np.sum(count > 2))} non-manifold edge(s) shared by more than two faces, "
                        f"first: ({int(bad[0])}, {int(bad[1])})")
    n_boundary = int(np.sum(count == 1))
    if n_boundary:
        warns.append(f"{name}: {n_boundary} boundary edge(s) (open surface; Laplacian uses Neumann boundary)")

    unused = np.setdiff1d(np.arange(len(V)), np.unique(F))
    if len(unused):
        warns.append(f"{name}: {len(unused)} vertex/vertices used by no face (e.g. {int(unused[0])})")

    used = np.unique(F)
    _, labels = vertex_components(len(V), F)
    n_comp = len(np.unique(labels[used]))
    if n_comp > 1:
        msg = (f"{name}: {n_comp} connected components; intrinsic distances between them are infinite "
               "(use meshcheck.largest_component to keep the main piece)")
        if not allow_components:
            raise MeshError(msg)
        warns.append(msg)
    return warns


def check_same_connectivity(F_a: np.ndarray, F_b: np.ndarray, name_a: str = "mesh A", name_b: str = "mesh B",
                            n_vertices_a: int | None = None, n_vertices_b: int | None = None) -> None:
    """Raise ``MeshError`` unless two meshes share vertex count and identical faces (same order).

    Needed when ground truth is "vertex i matches vertex i" (e.g. SCAPE poses).

    Args: F_a: (m_a,3) int; F_b: (m_b,3) int; names for messages; optional vertex counts.
    """
    if n_vertices_a is not None and n_vertices_b is not None and n_vertices_a != n_vertices_b:
        raise MeshError(f"{name_a} has {n_vertices_a} vertices but {name_b} has {n_vertices_b}; "
                        "the same connectivity is required")
    F_a = np.asarray(F_a)
    F_b = np.asarray(F_b)
    if F_a.shape != F_b.shape:
        raise MeshError(f"{name_a} has {len(F_a)} faces but {name_b} has {len(F_b)}; "
                        "the same connectivity is required")
    differ = np.flatnonzero(np.any(F_a != F_b, axis=1))
    if len(differ):
        k = int(differ[0])
        raise MeshError(f"{name_a} and {name_b} differ in {len(differ)} face(s), first: face {k} "
                        f"{F_a[k].tolist()} vs {F_b[k].tolist()}; the same connectivity is required")
