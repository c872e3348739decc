"""The pairwise operator of the joint-alignment MRF, W_ij(t1, t2) = exp(-Csym_ij(t2 - t1) / sigma), built from
pair costs C: (N, N, V) (``corr_core.alignment.pair_costs``) without ever storing the (NV x NV) matrix.

- ``CirculantPairwise``: the operator (corr_core.mrf protocol) on the complete graph (dense (N, N, V) float32
  kernel) or a symmetrized k-nearest graph (CSR + one (E, V) kernel row per directed edge);
- ``neighbor_graph``: that symmetrized kNN graph; ``symmetrize_costs``: Csym = (C + mirror(C)) / 2;
- ``dense_pairwise``: the same operator as an explicit ``DensePairwise`` (tests, small N).
"""
from __future__ import annotations

import numpy as np

from corr_core.alignment.pair_costs import mirror_pair_costs
from corr_core.mrf import DensePairwise

__all__ = ["CirculantPairwise", "neighbor_graph", "symmetrize_costs", "dense_pairwise"]


def _neighbor_mask(N: int, neighbors: np.ndarray | None) -> np.ndarray:
    mask = np.ones((N, N), dtype=bool)
    if neighbors is not None:
        neighbors = np.asarray(neighbors, dtype=np.int64)
        mask = np.zeros((N, N), dtype=bool)
        mask[np.repeat(np.arange(N), neighbors.shape[1]), neighbors.ravel()] = True
        mask |= mask.T
    mask[np.arange(N), np.arange(N)] = False
    return mask


def symmetrize_costs(C: np.ndarray) -> np.ndarray:
    """(N, N, V) float64 (C + mirror(C)) / 2: the symmetric part, Csym_ij(t) == Csym_ji(-t)."""
    C = np.asarray(C, dtype=np.float64)
    if C.ndim != 3 or C.shape[0] != C.shape[1]:
        raise ValueError(f"C must have shape (N, N, V), got {C.shape}")
    return 0.5 * (C + mirror_pair_costs(C))


def _check_costs(C: np.ndarray, sigma: float) -> np.ndarray:
    C = np.asarray(C)
    if C.ndim != 3 or C.shape[0] != C.shape[1]:
        raise ValueError(f"C must have shape (N, N, V), got {C.shape}")
    if not sigma > 0:
        raise ValueError(f"sigma must be > 0, got {sigma}")
    return C


def _rows_per_block(N: int, V: int, *, budget_bytes: int = 32 << 20) -> int:
    """Rows of an (N, V) float64 slab per block so that one block's temporaries stay near ``budget_bytes``."""
    return max(1, budget_bytes // (8 * N * V))


def _kernel(C: np.ndarray, sigma: float, neighbors: np.ndarray | None) -> np.ndarray:
    """K: (N, N, V) float32, K[i,j,t] = exp(-Csym_ij(t)/sigma), Csym = (C + mirror(C))/2, zero on the diagonal
    and off the graph. Built in row blocks: peak extra memory is one block, not a float64 copy of C.

    float32 is enough: C itself is float32 (pair_costs), and Csym_ij(t) and Csym_ji(-t) are the same float sums
    (a+b == b+a), so K[j,i,-t] == K[i,j,t] exactly and the operator stays exactly symmetric."""
    C = _check_costs(C, sigma)
    N, _, V = C.shape
    mask = _neighbor_mask(N, neighbors)
    K = np.empty((N, N, V), dtype=np.float32)
    minus_t = (-np.arange(V)) % V
    step = _rows_per_block(N, V)
    for r0 in range(0, N, step):
        r1 = min(N, r0 + step)
        rows = C[r0:r1].astype(np.float64) + C[:, r0:r1][:, :, minus_t].transpose(1, 0, 2)
        rows *= -0.5 / sigma
        np.exp(rows, out=rows)
        rows *= mask[r0:r1, :, None]
        K[r0:r1] = rows
    return K


def _edge_kernel(C: np.ndarray, sigma: float, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """(E, V) float32 kernel K_ij(t) of the edges (rows[e], cols[e]), same values as ``_kernel``."""
    V = C.shape[2]
    minus_t = (-np.arange(V)) % V
    out = np.empty((rows.size, V), dtype=np.float32)
    step = max(1, (32 << 20) // (8 * V))
    for e0 in range(0, rows.size, step):
        i, j = rows[e0:e0 + step], cols[e0:e0 + step]
        csym = C[i, j].astype(np.float64) + C[j, i][:, minus_t]
        out[e0:e0 + step] = np.exp(csym * (-0.5 / sigma))
    return out


def neighbor_graph(N: int, neighbors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Symmetrized k-nearest graph as CSR arrays (indptr (N+1,), indices (E,)): j is a neighbour of i iff
    j in neighbors[i] or i in neighbors[j], i != j; each row's indices sorted ascending."""
    neighbors = np.asarray(neighbors, dtype=np.int64)
    i = np.repeat(np.arange(N), neighbors.shape[1])
    j = neighbors.ravel()
    keys = np.unique(np.concatenate([i * N + j, j * N + i]))
    rows, cols = keys // N, keys % N
    keep = rows != cols
    rows, cols = rows[keep], cols[keep]
    indptr = np.zeros(N + 1, dtype=np.int64)
    np.add.at(indptr, rows + 1, 1)
    return np.cumsum(indptr), cols


class CirculantPairwise:
    """Pairwise operator (corr_core.mrf protocol) of the alignment MRF: W[i,j,a,b] = K_ij((b-a)%V),
    K_ij(t) = exp(-C_ij(t)/sigma), for N shapes x V labels, never stored as (NV x NV).

    C: (N, N, V) pair costs (symmetrized as (C + mirror(C))/2 so that W[i,j,a,b] == W[j,i,b,a]);
    neighbors: optional (N, k) int, keep only pairs (i, j) with j in neighbors[i] or i in neighbors[j].

    Storage: without neighbors the kernel is dense, K: (N, N, V) float32 (4 N^2 V bytes: 1.6 GB at N=5000,
    V=16). With neighbors it is sparse: the symmetrized graph in CSR form (indptr, indices) and one (E, V)
    float32 kernel row per directed edge, E <= 2 N k, so memory is O(N k V) and nothing of size N^2 is kept.

    matvec: Y[i,a] = sum_j sum_t K_ij(t) X[j,(a+t)%V]. With Xr[(j,t), a] = X[j,(a+t)%V] (an (NV, V) matrix)
    this is one product K.reshape(N, NV) @ Xr: dense float64 GEMMs over row blocks of K (upcast block by
    block, so accumulation is float64 and no float64 copy of K exists), or a scipy CSR (N, NV) @ Xr product
    for the sparse graph. O(N^2 V^2) dense resp. O(E V^2) sparse flops.
    """

    def __init__(self, C: np.ndarray, sigma: float, neighbors: np.ndarray | None = None):
        C = _check_costs(C, sigma)
        self.sigma = float(sigma)
        if neighbors is None:
            self._init_dense(_kernel(C, sigma, None))
        else:
            indptr, indices = neighbor_graph(C.shape[0], neighbors)
            rows = np.repeat(np.arange(C.shape[0]), np.diff(indptr))
            self._init_sparse(indptr, indices, _edge_kernel(C, sigma, rows, indices), C.shape[0])

    @classmethod
    def from_kernel(cls, K: np.ndarray, sigma: float = float("nan"), copy: bool = True) -> "CirculantPairwise":
        """Operator with W[i,j,a,b] = K[i,j,(b-a)%V] for any real K: (N,N,V) with K[j,i,t] == K[i,j,-t];
        the diagonal is zeroed. Dense storage (float32 if K is float32, else float64). ``copy=False`` wraps a
        fresh array the caller hands over (no copy of an N^2 V kernel; its diagonal is zeroed in place).
        ``sigma``: the kernel width K was built with, if any (kept as ``.sigma``)."""
        self = cls.__new__(cls)
        dtype = np.float32 if np.asarray(K).dtype == np.float32 else np.float64
        K = np.array(K, dtype=dtype, copy=True) if copy else np.asarray(K, dtype=dtype)
        K[np.arange(K.shape[0]), np.arange(K.shape[0])] = 0.0
        self._init_dense(K)
        self.sigma = float(sigma)
        return self

    @classmethod
    def from_edges(cls, indptr: np.ndarray, indices: np.ndarray, K_edges: np.ndarray,
                   sigma: float = float("nan")) -> "CirculantPairwise":
        """Sparse operator from a symmetric CSR graph (indptr (N+1,), indices (E,)) and per-edge kernels
        K_edges: (E, V) with K_edges[e(j,i)] == K_edges[e(i,j)][-t] (not checked)."""
        self = cls.__new__(cls)
        self._init_sparse(np.asarray(indptr, np.int64), np.asarray(indices, np.int64), np.asarray(K_edges),
                          len(indptr) - 1)
        self.sigma = float(sigma)
        return self

    def _init_common(self, N: int, V: int) -> None:
        self.n_nodes, self.n_labels = N, V
        a = np.arange(V)
        self._shift = (a[None, :] + a[:, None]) % V  # [t, a] -> (a + t) % V
        self._minus_a = -a

    def _init_dense(self, K: np.ndarray) -> None:
        self._init_common(K.shape[0], K.shape[2])
        self.sparse = False
        self._K = K

    def _init_sparse(self, indptr: np.ndarray, indices: np.ndarray, K_edges: np.ndarray, N: int) -> None:
        import scipy.sparse as sp
        V = K_edges.shape[1]
        self._init_common(N, V)
        self.sparse = True
        self.indptr, self.indices, self.K_edges = indptr, indices, K_edges
        cols = (indices[:, None] * V + np.arange(V)[None, :]).ravel()
        self._S = sp.csr_matrix((K_edges.astype(np.float64).ravel(), cols, indptr * V), shape=(N, N * V))

    @property
    def K(self) -> np.ndarray:
        """Dense kernel (N, N, V) (materialized from the edges for a sparse operator: small N only)."""
        if not self.sparse:
            return self._K
        N, V = self.n_nodes, self.n_labels
        K = np.zeros((N, N, V), dtype=self.K_edges.dtype)
        K[np.repeat(np.arange(N), np.diff(self.indptr)), self.indices] = self.K_edges
        return K

    @property
    def nbytes(self) -> int:
        """Bytes held by the kernel storage."""
        if not self.sparse:
            return int(self._K.nbytes)
        return int(self.K_edges.nbytes + self._S.data.nbytes + self._S.indices.nbytes + self.indices.nbytes)

    def _unrolled(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, dtype=np.float64)
        return X[:, self._shift].reshape(self.n_nodes * self.n_labels, self.n_labels)

    def matvec(self, X: np.ndarray) -> np.ndarray:
        """Y: (N, V), Y[i,a] = sum_{j,b} W[i,j,a,b] X[j,b]."""
        Xr = self._unrolled(X)
        if self.sparse:
            return np.asarray(self._S @ Xr)
        N, V = self.n_nodes, self.n_labels
        K2 = self._K.reshape(N, N * V)
        if K2.dtype == np.float64:
            return K2 @ Xr
        Y = np.empty((N, V))
        step = _rows_per_block(N, V)
        for r0 in range(0, N, step):
            Y[r0:r0 + step] = K2[r0:r0 + step].astype(np.float64) @ Xr
        return Y

    def column(self, j: int, b: int) -> np.ndarray:
        """W[:, j, :, b] = K[:, j, (b - a) % V] over a: (N, V) float64; O(N V) dense, O(deg(j) V) sparse."""
        V = self.n_labels
        if not self.sparse:
            return self._K[:, j, (b + self._minus_a) % V].astype(np.float64)
        # K_ij((b-a)%V) = K_ji((a-b)%V): row j of the CSR holds the reverse neighbours too (symmetric graph)
        s, e = self.indptr[j], self.indptr[j + 1]
        out = np.zeros((self.n_nodes, V))
        out[self.indices[s:e]] = self.K_edges[s:e][:, (np.arange(V) - b) % V]
        return out

    def block_max(self) -> np.ndarray:
        """(N, N) float64: max_t K_ij(t) (0 off the graph)."""
        if not self.sparse:
            return self._K.max(axis=2).astype(np.float64)
        B = np.zeros((self.n_nodes, self.n_nodes))
        B[np.repeat(np.arange(self.n_nodes), np.diff(self.indptr)), self.indices] = self.K_edges.max(axis=1)
        return B

    def harmonic(self, *, h: int = 1):
        """H: (N, N) complex128 Hermitian, H_ij = sum_t K_ij(t) exp(+i 2 pi h t / V): a dense ndarray, or a
        scipy.sparse CSR matrix for a sparse operator (the input of spectral synchronization)."""
        V = self.n_labels
        phase = np.exp(2j * np.pi * h * np.arange(V) / V)
        if self.sparse:
            import scipy.sparse as sp
            data = self.K_edges.astype(np.float64) @ phase
            return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n_nodes, self.n_nodes))
        N = self.n_nodes
        H = np.empty((N, N), dtype=np.complex128)
        basis = np.stack([phase.real, phase.imag], axis=1)  # (V, 2): real GEMMs, no complex copy of K
        step = _rows_per_block(N, V)
        for r0 in range(0, N, step):
            R = self._K[r0:r0 + step].astype(np.float64) @ basis
            H[r0:r0 + step] = R[..., 0] + 1j * R[..., 1]
        return H


def dense_pairwise(C: np.ndarray, sigma: float, neighbors: np.ndarray | None = None) -> DensePairwise:
    """The same operator as CirculantPairwise(C, sigma, neighbors) as an explicit (N, N, V, V) DensePairwise
    (small N only), built from the same float32 kernel values."""
    K = _kernel(C, sigma, neighbors).astype(np.float64)
    V = K.shape[2]
    a = np.arange(V)
    return DensePairwise(K[:, :, (a[None, :] - a[:, None]) % V])
