"""Checks that a mesh is fit for intrinsic (Laplacian / geodesic) correspondence, after ``repair.repair_mesh``.

Errors (``MeshError``): degenerate faces (``repair_mesh`` drops them), several connected components (unless
``allow_components``), vertices used by no face (unless ``allow_unreferenced``), different connectivity where it
must be equal. Warnings (returned strings): non-manifold edges (the cotan Laplacian, the heat method and the
mid-edge flattening still run on them), boundary edges, unreferenced vertices / components when allowed.
"""
from __future__ import annotations

import numpy as np

from corr_core.geometry.mesh_io import MeshError, check_mesh, counted
from corr_core.geometry.primitives import face_areas, unique_edges, vertex_components


def check_correspondence_mesh(V: np.ndarray, F: np.ndarray, name: str = "mesh",
                              allow_components: bool = False, *, area_tol: float = 1e-12,
                              allow_unreferenced: bool = True) -> list[str]:
    """Validate a mesh for spectral / geodesic correspondence.

    Args:
        V: (n,3) float; F: (m,3) int; name: used in messages (e.g. the file name).
        allow_components: if True, several connected components give a warning instead of an error.
        allow_unreferenced: if False, vertices used by no face are an error (the heat-method geodesics and the
            mid-edge flattening need every vertex on the surface).
        area_tol: a face is degenerate when its area <= area_tol * (bounding-box diagonal)^2 or it repeats a
            vertex.
    Returns:
        list of warning strings (non-manifold edges, boundary, unreferenced vertices / components when allowed).
    Raises:
        MeshError: basic problems (see ``mesh_io.check_mesh``), degenerate faces, several connected components,
        unreferenced vertices (each unless allowed).
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    check_mesh(V, F, name=name)
    warns: list[str] = []

    repeated = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    used_V = V[np.unique(F)]  # unreferenced vertices (maybe far away) must not set the scale
    diag2 = float(np.sum((used_V.max(0) - used_V.min(0)) ** 2))
    degenerate = repeated | (face_areas(V, F) <= area_tol * max(diag2, np.finfo(float).tiny))
    if degenerate.any():
        ids = np.flatnonzero(degenerate)
        raise MeshError(f"{name}: {len(ids)} degenerate (zero-area) face(s), first: face {int(ids[0])}; "
                        "the cotan Laplacian is undefined there — load the mesh with repair.repair_mesh, which drops them")

    E, count = unique_edges(F)
    if np.any(count > 2):
        bad = E[np.flatnonzero(count > 2)[0]]
        warns.append(f"{name}: {int(np.sum(count > 2))} non-manifold edge(s) shared by more than two faces, "
                     f"first: ({int(bad[0])}, {int(bad[1])}); kept (results near them may be less accurate)")
    n_boundary = int(np.sum(count == 1))
    if n_boundary:
        warns.append(f"{name}: {counted(n_boundary, 'boundary edge')} (open surface; Laplacian uses Neumann boundary)")

    unused = np.setdiff1d(np.arange(len(V)), np.unique(F))
    if len(unused):
        msg = f"{name}: {counted(len(unused), 'vertex', 'vertices')} used by no face (e.g. {int(unused[0])})"
        if not allow_unreferenced:
            raise MeshError(msg + "; the geodesic and flattening methods need every vertex on the surface: "
                            "remove the unused vertices (or the stray pieces) from the file")
        warns.append(msg)

    used = np.unique(F)
    _, labels = vertex_components(len(V), F)
    n_comp = len(np.unique(labels[used]))
    if n_comp > 1:
        msg = (f"{name}: {n_comp} connected components; intrinsic distances between them are infinite "
               "(remove the stray pieces from the file, keeping the largest connected component)")
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
