"""Nearest target vertex whose normal agrees: the closest-point query every refinement step shares; the exact
3-D point tree behind it (``PointTree``); the cells of ``fmaps.nearest_rows``' pruned spectral search
(``RowCells``)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pykdtree.kdtree import KDTree


@dataclass(frozen=True)
class RowCells:
    """A partition of the rows of a point set into cells, for ``nearest_rows``' exact pruned search.

    Attributes:
        centres: (c,) int the row of each cell's centre (a row of the points).
        owner: (p,) int the cell of every row (index into ``centres``; a centre owns itself).
        rank: (c,) int position of each cell in an order that keeps neighbouring cells together (queries whose
            nearest centres are close in this order are searched together).
    Any partition gives the exact nearest rows; one of compact cells (``MeshBasis.vertex_cells``: each vertex
    with its nearest sample) makes the search fast.
    """
    centres: np.ndarray
    owner: np.ndarray
    rank: np.ndarray


class PointTree:
    """Exact nearest points of a fixed 3-D point set: ``PointTree(points)`` with points (n,3) float;
    ``query(P, *, k=1)``: P (q,3) -> distances (q,) float and ids (q,) int64 for k = 1, (q,k) each for k > 1 (nearest
    first, k clipped to n), as ``scipy.spatial.cKDTree.query``.

    pykdtree's k-d tree: on the refinement's queries it takes 0.62-0.64 of cKDTree's time with the same answers
    (``bench/dense_searches.py``, "vertices"); equidistant points may come in another order than cKDTree's.
    Its OpenMP threads follow OMP_NUM_THREADS (1 in the engine's workers); each query's answer depends only on
    its point, never on the threads."""

    def __init__(self, points: np.ndarray):
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        if self.points.ndim != 2 or self.points.shape[1] != 3 or not len(self.points):
            raise ValueError(f"PointTree: need (n >= 1, 3) points, got shape {self.points.shape}")
        self._tree = KDTree(self.points)

    def query(self, P: np.ndarray, *, k: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Distances and ids of the ``k`` nearest points of each row of P (q,3) (see the class)."""
        P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
        d, ids = self._tree.query(P, k=int(min(k, len(self.points))))
        return d, ids.astype(np.int64)


def nearest_compatible(tree: PointTree, normals_t: np.ndarray, P: np.ndarray, normals_p: np.ndarray, *,
                       min_cos: float, k: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Nearest target vertex to each point P (q,3) among its ``k`` nearest whose normal (n_t,3) makes a cosine
    > ``min_cos`` with the point's normal (q,3): (ids (q,) int, distances (q,) float, inf when none qualifies).

    ``tree`` is a ``PointTree`` of the target vertices (n_t,3). The normal test rejects a touching body part (it faces
    the other way) and the other side of a thin part.

    Most points' nearest vertex already agrees, so the two nearest are found first: a point whose nearest agrees
    and is strictly nearer than the second has its answer; only the others search among ``k``. The answers are
    those of the search among ``k`` for every point (half the time when nearly all agree)."""
    k = min(k, len(normals_t))
    if k < 2:
        return _nearest_compatible_among(tree, normals_t, P, normals_p, min_cos, k)
    d, c = tree.query(P, k=2)
    ids, dist = c[:, 0], d[:, 0]
    settled = (np.einsum("ij,ij->i", normals_p, normals_t[ids]) > min_cos) & (d[:, 1] > d[:, 0])
    rest = np.flatnonzero(~settled)
    if len(rest):
        ids[rest], dist[rest] = _nearest_compatible_among(tree, normals_t, P[rest], normals_p[rest], min_cos, k)
    return ids, dist


def _nearest_compatible_among(tree: PointTree, normals_t: np.ndarray, P: np.ndarray, normals_p: np.ndarray,
                              min_cos: float, k: int) -> tuple[np.ndarray, np.ndarray]:
    """``nearest_compatible`` by one search among the ``k`` nearest of every point (ties: the k-d tree's order)."""
    d, c = tree.query(P, k=k)
    d, c = d.reshape(len(P), -1), c.reshape(len(P), -1)
    d = np.where(np.einsum("ij,ikj->ik", normals_p, normals_t[c]) > min_cos, d, np.inf)
    best = np.argmin(d, axis=1)
    rows = np.arange(len(P))
    return c[rows, best], d[rows, best]


class VertexNeighbourhoods:
    """The ``k`` vertices nearest (3D) to each of a mesh's vertices, each vertex's row found by one k-d tree query
    the first time it is asked for and then kept. A refinement asks for the neighbourhoods of a map's images in
    every round (``refine.upsample_spectral``, ``refine.refine_spectral``), and most images repeat: within a map
    (an upsampled map has one image per template sample) and from one round or starting map to the next. The rows
    are those of ``PointTree(V).query(V[ids], k)``, bit for bit (a query's answer depends only on its point).

    ``VertexNeighbourhoods(V, k, tree=None)``: V (n,3) float; k clipped to n; tree: a ``PointTree`` of V to share
    (None: one is made). ``of(ids)``: ids (q,) int vertex ids ->
    (q, k) int neighbour ids, nearest first."""

    def __init__(self, V: np.ndarray, k: int, tree: PointTree | None = None):
        self.V = np.asarray(V, dtype=np.float64)
        self.k = int(min(k, len(self.V)))
        if self.k < 1:
            raise ValueError(f"VertexNeighbourhoods: need k >= 1 and at least one vertex, got k={k}, {len(V)} "
                             f"vertices")
        self._tree = PointTree(self.V) if tree is None else tree
        self._rows = np.empty((len(self.V), self.k), dtype=np.int64)
        self._known = np.zeros(len(self.V), dtype=bool)

    def of(self, ids: np.ndarray) -> np.ndarray:
        """(q, k) int: the k nearest vertices of each vertex of ``ids`` (q,) int."""
        ids = np.asarray(ids, dtype=np.int64)
        new = np.unique(ids[~self._known[ids]])
        if len(new):
            _, rows = self._tree.query(self.V[new], k=self.k)
            self._rows[new] = rows.reshape(len(new), self.k)
            self._known[new] = True
        return self._rows[ids]


def vertex_neighbourhoods(basis, k: int) -> VertexNeighbourhoods:
    """The ``VertexNeighbourhoods`` of a ``MeshBasis``'s vertices for ``k``, made once per basis (cached on it: the
    starting maps of a pair and every refinement step share it)."""
    k = int(min(k, basis.n))
    return basis.cached(("vertex_neighbourhoods", k), lambda: VertexNeighbourhoods(basis.V, k, basis.tree()))
