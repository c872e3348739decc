"""Pair costs on a candidate graph: C_ij(theta) for a list of pairs instead of an (N, N, V) matrix.

``GraphCosts`` holds, for N shapes and V views, the computed pairs i < j (rows, cols: (P,) int64), their costs
(P, V) float32 (C_ij(theta) in the conventions of ``corr_core.alignment.pair_costs``; C_ji(theta) = C_ij(-theta)
is implied), each shape's self costs C_ii (N, V) when they were computed (symmetry detection), and which pairs
are a uniform random sample of all pairs (``sample``, for the kernel width). Memory is O(P V), never O(N^2).

What the dense solvers read off C, this module reads off the pairs: ``auto_sigma`` (median of min_theta C_ij,
over the random sample when it is large enough: an unbiased estimate of the complete graph's value),
``operator`` (the MRF's ``CirculantPairwise`` on the graph, with the kernel values of the dense operator
restricted to that graph, bit for bit), ``shifted`` (the costs after shifting the shapes' views, for
equivariance), ``harmonic`` (the k-th harmonic matrix, sparse). ``from_dense`` restricts a dense C to a graph.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corr_core.alignment.circulant import CirculantPairwise

__all__ = ["GraphCosts", "from_dense", "from_pair_list", "from_candidates", "SIGMA_SAMPLE_MIN"]

# the random sample gives the kernel width only when it has at least this many pairs
SIGMA_SAMPLE_MIN = 50


@dataclass(frozen=True)
class GraphCosts:
    """Pair costs of N shapes on a graph (see the module docstring).

    n: shapes; rows, cols: (P,) int64 with rows < cols, sorted by (row, col), unique; costs: (P, V) float32;
    self_costs: (N, V) float32 C_ii or None; sample: (P,) bool, the pairs drawn uniformly at random (or None).
    """
    n: int
    rows: np.ndarray
    cols: np.ndarray
    costs: np.ndarray
    self_costs: np.ndarray | None = None
    sample: np.ndarray | None = None

    def __post_init__(self):
        P = len(self.rows)
        if self.costs.ndim != 2 or len(self.costs) != P or len(self.cols) != P:
            raise ValueError(f"graph costs: rows ({len(self.rows)}), cols ({len(self.cols)}) and costs "
                             f"{self.costs.shape} must describe the same P pairs as (P,), (P,), (P, V)")
        if P and not (np.all(self.rows < self.cols) and self.rows.min() >= 0 and self.cols.max() < self.n):
            raise ValueError(f"graph costs: every pair must be (i, j) with 0 <= i < j < N = {self.n}")
        if self.self_costs is not None and self.self_costs.shape != (self.n, self.costs.shape[1]):
            raise ValueError(f"graph costs: self_costs must be (N, V) = {(self.n, self.costs.shape[1])}, "
                             f"got {self.self_costs.shape}")

    @property
    def n_views(self) -> int:
        return int(self.costs.shape[1])

    @property
    def n_pairs(self) -> int:
        return int(len(self.rows))

    @property
    def nbytes(self) -> int:
        extra = 0 if self.self_costs is None else self.self_costs.nbytes
        return int(self.rows.nbytes + self.cols.nbytes + self.costs.nbytes + extra)

    def best(self) -> np.ndarray:
        """(P,) float64 min_theta C_ij(theta) of every pair."""
        return self.costs.min(axis=1).astype(np.float64)

    def auto_sigma(self) -> float:
        """Kernel width: median of min_theta C_ij over the random sample (>= SIGMA_SAMPLE_MIN pairs), else over
        all pairs; falls back like ``pair_costs.auto_sigma`` (mean of positive values, then 1.0)."""
        best = self.best()
        if self.sample is not None and int(np.sum(self.sample)) >= SIGMA_SAMPLE_MIN:
            best = best[self.sample]
        if best.size == 0:
            return 1.0
        sigma = float(np.median(best))
        if sigma > 0:
            return sigma
        positive = best[best > 0]
        return float(positive.mean()) if positive.size else 1.0

    def directed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(indptr (N+1,), indices (2P,), order (2P,)): the symmetric CSR layout of the graph (each row's columns
        ascending, as ``circulant.neighbor_graph``); order[e] = p for edge (rows[p], cols[p]) and P + p for its
        reverse (cols[p], rows[p])."""
        src = np.concatenate([self.rows, self.cols])
        dst = np.concatenate([self.cols, self.rows])
        order = np.lexsort((dst, src))
        indptr = np.zeros(self.n + 1, np.int64)
        np.add.at(indptr, src + 1, 1)
        return np.cumsum(indptr), dst[order], order

    def edge_kernel(self, sigma: float, costs: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(indptr, indices, K_edges (2P, V) float32) with K_ij(t) = exp(-C_ij(t)/sigma) computed exactly as the
        dense operator does (Csym = C_ij(t) + C_ji(-t) = 2 C_ij(t) in float64, times -0.5/sigma) and
        K_ji(t) = K_ij(-t). costs: other (P, V) values on the same pairs (default: self.costs)."""
        if not sigma > 0:
            raise ValueError(f"sigma must be > 0, got {sigma}")
        costs = self.costs if costs is None else costs
        V = costs.shape[1]
        minus_t = (-np.arange(V)) % V
        K = np.empty((len(costs), V), np.float32)
        step = max(1, (32 << 20) // (8 * V))
        for s in range(0, len(costs), step):
            c = costs[s:s + step].astype(np.float64)
            K[s:s + step] = np.exp((c + c) * (-0.5 / sigma))
        indptr, indices, order = self.directed()
        both = np.concatenate([K, K[:, minus_t]])
        return indptr, indices, both[order]

    def operator(self, sigma: float, costs: np.ndarray | None = None) -> CirculantPairwise:
        """The MRF's pairwise operator on this graph (sparse ``CirculantPairwise``)."""
        indptr, indices, K = self.edge_kernel(sigma, costs)
        return CirculantPairwise.from_edges(indptr, indices, K, sigma=sigma)

    def with_costs(self, costs: np.ndarray) -> "GraphCosts":
        """The same graph with other (P, V) costs (self costs and sample kept)."""
        return GraphCosts(self.n, self.rows, self.cols, np.asarray(costs, np.float32), self.self_costs, self.sample)

    def shifted(self, shifts: np.ndarray) -> "GraphCosts":
        """Costs after cyclically shifting shape i's views by shifts[i] (N,) int (as ``pair_costs.shift_costs``:
        C'_ij(theta) = C_ij(theta + s_i - s_j); self costs unchanged)."""
        V = self.n_views
        shifts = np.asarray(shifts, np.int64)
        idx = (np.arange(V)[None, :] + (shifts[self.rows] - shifts[self.cols])[:, None]) % V
        return self.with_costs(np.take_along_axis(self.costs, idx, axis=1))

    def pair_cost(self, i: int, j: int) -> np.ndarray | None:
        """(V,) C_ij(theta) for a pair on the graph (either order), or None when (i, j) is not a pair."""
        a, b = (i, j) if i < j else (j, i)
        lo, hi = np.searchsorted(self.rows, [a, a + 1])
        p = lo + np.searchsorted(self.cols[lo:hi], b)
        if p >= hi or self.cols[p] != b:
            return None
        c = self.costs[p]
        return c if i < j else c[(-np.arange(self.n_views)) % self.n_views]

    def neighbor_costs(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """(neighbours (m,) int64, costs (m, V) float32 C_{i,j}(theta) for each neighbour j) of shape i."""
        V = self.n_views
        as_row = np.flatnonzero(self.rows == i)
        as_col = np.flatnonzero(self.cols == i)
        nbrs = np.concatenate([self.cols[as_row], self.rows[as_col]])
        costs = np.concatenate([self.costs[as_row], self.costs[as_col][:, (-np.arange(V)) % V]])
        return nbrs, costs

    def harmonic(self, sigma: float, *, h: int = 1):
        """H: (N, N) scipy.sparse CSR complex Hermitian, H_ij = sum_t K_ij(t) exp(+i 2 pi h t / V)."""
        return self.operator(sigma).harmonic(h=h)

    def subgraph(self, nodes: np.ndarray) -> "GraphCosts":
        """The graph costs of the shapes ``nodes`` (sorted (m,) int) among themselves, renumbered 0..m-1."""
        nodes = np.asarray(nodes, np.int64)
        index = np.full(self.n, -1, np.int64)
        index[nodes] = np.arange(len(nodes))
        keep = (index[self.rows] >= 0) & (index[self.cols] >= 0)
        return GraphCosts(len(nodes), index[self.rows[keep]], index[self.cols[keep]], self.costs[keep],
                          None if self.self_costs is None else self.self_costs[nodes],
                          None if self.sample is None else self.sample[keep])


def from_pair_list(n: int, pairs: np.ndarray, costs: np.ndarray, sample: np.ndarray | None = None) -> GraphCosts:
    """GraphCosts from computed pairs (P, 2) int (either order; (i, i) pairs become self costs) and their costs
    (P, V) (C_{pairs[p, 0], pairs[p, 1]}). A pair given in both orders keeps its first occurrence; sample: (P,)
    bool of the randomly drawn pairs (or None)."""
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    costs = np.asarray(costs, np.float32)
    if len(costs) != len(pairs) or costs.ndim != 2:
        raise ValueError(f"{len(pairs)} pairs but costs of shape {costs.shape}: expected ({len(pairs)}, V)")
    if len(pairs) and (pairs.min() < 0 or pairs.max() >= n):
        raise ValueError(f"pairs index shapes outside 0..{n - 1}")
    V = costs.shape[1]
    diag = pairs[:, 0] == pairs[:, 1]
    self_costs = None
    if diag.any():
        self_costs = np.full((n, V), np.nan, np.float32)
        self_costs[pairs[diag, 0]] = costs[diag]
        if np.isnan(self_costs).any():
            self_costs = None  # only some shapes have their self costs: symmetry cannot be read for all
    off = ~diag
    swap = pairs[off, 0] > pairs[off, 1]
    i = np.where(swap, pairs[off, 1], pairs[off, 0])
    j = np.where(swap, pairs[off, 0], pairs[off, 1])
    c = costs[off]
    c = np.where(swap[:, None], c[:, (-np.arange(V)) % V], c)
    key = i * n + j
    order = np.argsort(key, kind="stable")
    first = np.concatenate([[True], key[order][1:] != key[order][:-1]]) if len(order) else np.zeros(0, bool)
    keep = order[first]
    smp = None if sample is None else np.asarray(sample, bool)[off][keep]
    return GraphCosts(int(n), i[keep], j[keep], np.ascontiguousarray(c[keep]), self_costs, smp)


def from_dense(C: np.ndarray, pairs: np.ndarray | None = None, sample: np.ndarray | None = None) -> GraphCosts:
    """GraphCosts of a dense C: (N, N, V) restricted to ``pairs`` (P, 2) (default: every pair i < j), with the
    self costs C_ii."""
    C = np.asarray(C)
    N = C.shape[0]
    if pairs is None:
        i, j = np.triu_indices(N, 1)
        pairs = np.stack([i, j], axis=1)
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    gc = from_pair_list(N, pairs, C[pairs[:, 0], pairs[:, 1]], sample)
    return GraphCosts(gc.n, gc.rows, gc.cols, gc.costs, C[np.arange(N), np.arange(N)].astype(np.float32),
                      gc.sample)


def from_candidates(names: list[str], pairs: np.ndarray, values: np.ndarray, graph: dict | None = None) -> GraphCosts:
    """GraphCosts of N shapes ``names`` from computed pairs (P, 2) int indices into names (i < j) and their values
    (P, V) C_ij(theta), with what the candidate graph ``graph`` knows (optional; a dict with "names" (M,),
    "pairs" (Q, 2) indices into its names, "kind" (Q,) ``candidates.PAIR_KINDS`` codes and "self_costs" (M, V)):
    which pairs were drawn at random (``sample``) and each shape's self costs C_ii. Shapes of ``names``
    missing from the graph's names (or graph None) leave the self costs out (symmetry is then not detected)."""
    from corr_core.alignment.candidates import SAMPLE_KINDS

    N = len(names)
    values = np.asarray(values, np.float32)
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    if values.ndim != 2:
        raise ValueError(f"pair costs must be (P, V) for P = {len(pairs)} pairs, got shape {values.shape}")
    sample = self_costs = None
    if graph is not None:
        index = {n: i for i, n in enumerate(names)}
        remap = np.array([index.get(n, -1) for n in graph["names"]], np.int64)
        gp = remap[np.asarray(graph["pairs"], np.int64).reshape(-1, 2)]
        drawn = np.isin(np.asarray(graph["kind"]), SAMPLE_KINDS) & np.all(gp >= 0, axis=1)
        lo, hi = np.minimum(gp[drawn, 0], gp[drawn, 1]), np.maximum(gp[drawn, 0], gp[drawn, 1])
        sample = np.isin(pairs[:, 0] * N + pairs[:, 1], lo * N + hi)
        if "self_costs" in graph and np.all(np.isin(np.arange(N), remap)):
            self_costs = np.empty((N, values.shape[1]), np.float32)
            keep = remap >= 0
            self_costs[remap[keep]] = np.asarray(graph["self_costs"], np.float32)[keep]
    gc = from_pair_list(N, pairs, values, sample)
    return GraphCosts(gc.n, gc.rows, gc.cols, gc.costs, self_costs, gc.sample)
