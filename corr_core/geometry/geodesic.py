"""Geodesic distances on triangle meshes by the heat method (potpourri3d / geometry-central).

The heat method is approximate (a few percent on coarse meshes, smoothed near the source); it is fast:
one sparse factorization per mesh, then two back-substitutions and one Poisson solve per source.
"""
from __future__ import annotations

import numpy as np

from corr_core.geometry.intrinsic import IntrinsicMesh


class GeodesicSolver:
    """Heat-method geodesic distances on one mesh (potpourri3d's ``MeshHeatMethodDistanceSolver``): the mesh is
    factorized once, then each source costs two back-substitutions and one Poisson solve.

    The solver works on the largest connected component of the referenced vertices (``IntrinsicMesh``); ids in
    and out are the original vertex ids, and vertices outside that component are at distance NaN (a source
    there raises ``OutsideComponentError``).

    V: (n,3) float; F: (m,3) int; t_coef: heat time as a multiple of the mean edge length squared.
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, *, t_coef: float = 1.0):
        import potpourri3d as pp3d

        self.n_vertices = len(V)
        self.surface = IntrinsicMesh(V, F)
        self._heat = pp3d.MeshHeatMethodDistanceSolver(
            np.ascontiguousarray(self.surface.V, dtype=np.float64),
            np.ascontiguousarray(self.surface.F, dtype=np.int64), t_coef=t_coef)

    def distance(self, source: int) -> np.ndarray:
        """(n,) float distance from vertex ``source`` to every vertex, length units of V (NaN off the surface)."""
        local = int(self.surface.to_sub([int(source)], what="source vertex")[0])
        return self.surface.to_full(self._heat.compute_distance(local))

    def distances(self, sources) -> np.ndarray:
        """(s, n) float distances from each of the (s,) int source vertices to every vertex."""
        sources = np.atleast_1d(np.asarray(sources, dtype=np.int64))
        n = self.n_vertices
        if len(sources) and (sources.min() < 0 or sources.max() >= n):
            raise ValueError(f"source ids must be in 0..{n - 1}")
        out = np.empty((len(sources), n))
        for row, s in enumerate(sources):
            out[row] = self.distance(int(s))
        return out

    def diameter(self, *, rounds: int = 3, start: int = 0) -> float:
        """Approximate geodesic diameter by repeated double sweeps (farthest point from a vertex, then from it).

        Each sweep can only raise the estimate; it is a lower bound of the true diameter that is usually tight
        on elongated shapes (humans: toe to fingertip / head). rounds: number of sweeps; start: first vertex (the
        surface's first vertex when ``start`` is off it).
        """
        v, best = int(start), 0.0
        if not self.surface.contains([v])[0]:
            v = int(self.surface.vids[0])  # the first vertex of the surface
        for _ in range(max(1, rounds)):
            d = self.distance(v)
            far = int(np.nanargmax(d))
            if d[far] <= best:
                break
            best, v = float(d[far]), far
        return best


def geodesic_distances(V: np.ndarray, F: np.ndarray, sources, solver: GeodesicSolver | None = None) -> np.ndarray:
    """(s, n) float geodesic distance from each source vertex (sources: (s,) int) to every vertex of V: (n,3),
    F: (m,3). solver: a ``GeodesicSolver`` of (V, F) to reuse its factorization."""
    return (GeodesicSolver(V, F) if solver is None else solver).distances(sources)


def geodesic_diameter(V: np.ndarray, F: np.ndarray, *, rounds: int = 3, start: int = 0,
                      solver: GeodesicSolver | None = None) -> float:
    """Approximate geodesic diameter of (V, F), length units of V (see ``GeodesicSolver.diameter``)."""
    return (GeodesicSolver(V, F) if solver is None else solver).diameter(rounds=rounds, start=start)


def landmark_geodesics(V: np.ndarray, F: np.ndarray, vids, normalize: bool = True) -> np.ndarray:
    """Pairwise geodesic distances between landmark vertices.

    Args:
        V: (n,3); F: (m,3); vids: (k,) int landmark vertex ids.
        normalize: divide by the surface's geodesic diameter (scale-free, comparable across shapes).
    Returns:
        (k,k) float, symmetric (the heat method's small asymmetry is averaged out), zero diagonal.
    """
    solver = GeodesicSolver(V, F)
    vids = np.asarray(vids, dtype=np.int64)
    D = solver.distances(vids)[:, vids]
    D = 0.5 * (D + D.T)
    np.fill_diagonal(D, 0.0)
    if normalize:
        D = D / solver.diameter()
    return D
