"""The surface that intrinsic methods work on: the largest connected component of the referenced vertices.

Eigenpairs, heat-method geodesics and the mid-edge flattening need one connected surface through every vertex
they are given: a vertex used by no face makes the Laplacian singular (NaN flattening, shape errors in the
geodesic solver) and a loose piece is a second surface. ``IntrinsicMesh`` keeps the largest component (by area,
``primitives.largest_component``) compacted to local ids ``0..k-1``, and maps between those and the original
vertex ids, so every result is expressed in the *original* ids (ground truth "vertex i <-> vertex i" and
landmark files keep their meaning): ``to_sub`` before computing, ``to_full`` / ``vids[...]`` after.
Faces hanging on a non-manifold edge (a fin standing on the surface: ``primitives.without_fins``) are left out
too, and with them the vertices only they use.

On a clean mesh (one component, every vertex used) it is the identity: ``V`` and ``F`` are the given arrays
and the results are bit-identical to computing on the mesh directly.
"""
from __future__ import annotations

import numpy as np

from corr_core.geometry.primitives import largest_component, vertex_components, without_fins

__all__ = ["IntrinsicMesh", "OutsideComponentError"]


class OutsideComponentError(ValueError):
    """A vertex that a computation needs lies outside the kept component."""


class IntrinsicMesh:
    """The largest connected component of (V, F), compacted, with the map to the original vertex ids.

    Attributes:
        vids: (k,) int64 original ids of the kept vertices, increasing.
        V: (k,3) float64 their positions (= V_full[vids]); F: (m',3) int64 the component's faces in local ids.
        n_full: number of vertices of the original mesh.
        is_identity: True when nothing is left out, no vertex and no face (then V, F are the original arrays).
    """

    def __init__(self, V: np.ndarray, F: np.ndarray):
        V = np.asarray(V, dtype=np.float64)
        F = np.asarray(F, dtype=np.int64)
        self.n_full = len(V)
        F_kept = without_fins(V, F)                  # a face hanging on a non-manifold edge is not surface
        used = np.unique(F_kept)
        if F_kept is F and len(used) == len(V) and _connected(len(V), F):
            self.V, self.F, self.vids = V, F, np.arange(len(V), dtype=np.int64)
            self.is_identity = True
        else:
            self.V, self.F, kept = largest_component(V, F_kept)
            self.vids = np.asarray(kept, dtype=np.int64)
            self.is_identity = False
        self._local = np.full(self.n_full, -1, dtype=np.int64)
        self._local[self.vids] = np.arange(len(self.vids))

    def contains(self, vids) -> np.ndarray:
        """(p,) bool: which of the original vertex ids (p,) int lie on the kept component."""
        vids = np.asarray(vids, dtype=np.int64)
        inside = (vids >= 0) & (vids < self.n_full)
        inside[inside] = self._local[vids[inside]] >= 0
        return inside

    def to_sub(self, vids, *, what: str = "vertex", names=None, source: str = "") -> np.ndarray:
        """Local ids (p,) int64 of the original vertex ids (p,) int.

        Raises OutsideComponentError naming the first vertex outside the kept component (``what``: e.g.
        "landmark"; ``names``: (p,) labels of the vertices; ``source``: the file they come from).
        """
        vids = np.asarray(vids, dtype=np.int64)
        inside = self.contains(vids)
        if not inside.all():
            i = int(np.flatnonzero(~inside)[0])
            label = f"{what} {names[i]!r} (vertex {int(vids[i])})" if names is not None else \
                f"{what} {int(vids[i])}"
            where = f" from {source}" if source else ""
            raise OutsideComponentError(
                f"{label}{where} is not on the mesh's largest connected component ({len(self.vids)} of "
                f"{self.n_full} vertices), which intrinsic methods use: it lies on a small loose piece or no face "
                f"uses it ({int((~inside).sum())} such {what}(s)); move the {what} onto the main surface or "
                "remove the loose piece")
        return self._local[vids]

    def to_full(self, values, fill=np.nan, *, axis: int = 0) -> np.ndarray:
        """Scatter per-kept-vertex values (k, ...) (along ``axis``) to all n_full vertices; the vertices
        outside the kept component get ``fill`` (NaN; use -1 for integer ids)."""
        values = np.asarray(values)
        if self.is_identity:
            return values
        values = np.moveaxis(values, axis, 0)
        dtype = np.result_type(values.dtype, np.min_scalar_type(fill) if np.isscalar(fill) else fill)
        out = np.full((self.n_full,) + values.shape[1:], fill, dtype=dtype)
        out[self.vids] = values
        return np.moveaxis(out, 0, axis)


def _connected(n_vertices: int, F: np.ndarray) -> bool:
    """Whether the faces F: (m,3) join all n_vertices vertices into one component."""
    return vertex_components(n_vertices, F)[0] == 1
