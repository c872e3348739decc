"""Defects of published meshes, made on purpose: what the repair and the dense maps must survive (tests, bench).

- ``cut_along_a_seam``: some faces get their own copies of the vertices they share with the others (a seam as
  texture exports write it: two pieces, vertices repeated with new ids).
- ``with_fins``: triangles standing on edges of the surface, each with a new apex vertex (the edge then has three
  faces: non-manifold).
Both append the new vertices after the mesh's own, so vertex i of the input stays vertex i.
"""
from __future__ import annotations

import numpy as np

__all__ = ["cut_along_a_seam", "with_fins"]


def cut_along_a_seam(V: np.ndarray, F: np.ndarray, side: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """V (n,3), F (m,3) with the faces of ``side`` ((m,) bool) given their own copies of the vertices they share
    with the other faces, appended after the others. Returns (V2 (n+s,3), F2 (m,3), shared (s,) original ids of the
    seam vertices, copies (s,) their new ids n..n+s-1)."""
    shared = np.intersect1d(np.unique(F[side]), np.unique(F[~side]))
    copies = len(V) + np.arange(len(shared))
    renumber = np.arange(len(V))
    renumber[shared] = copies
    F2 = F.copy()
    F2[side] = renumber[F[side]]
    return np.vstack([V, V[shared]]), F2, shared, copies


def with_fins(V: np.ndarray, F: np.ndarray, n_fins: int, *, seed: int = 0, height: float = 0.5
              ) -> tuple[np.ndarray, np.ndarray]:
    """V (n,3), F (m,3) with ``n_fins`` fins: a triangle standing on the first edge of a random face (``seed``),
    its apex a new vertex ``height`` x the face's mean edge length out along the face normal. Returns (V2 (n+f,3),
    F2 (m+f,3): the faces of F first, then the fins; apexes n..n+f-1)."""
    faces = np.random.default_rng(seed).choice(len(F), n_fins, replace=False)
    a, b, c = (V[F[faces, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    edge = (np.linalg.norm(b - a, axis=1) + np.linalg.norm(c - b, axis=1) + np.linalg.norm(a - c, axis=1)) / 3
    apex = (a + b + c) / 3 + height * edge[:, None] * normal
    fins = np.column_stack([F[faces, 0], F[faces, 1], len(V) + np.arange(n_fins)])
    return np.vstack([V, apex]), np.vstack([F, fins])
