"""Rotation costs between shapes seen from V azimuths, and the alignment MRF built from them.

Conventions (fixed for the whole project):

- View k of a shape is seen from azimuth 2*pi*k/V about +y. If shape j is shape i rotated about +y by s
  steps, then views_j[(k+s)%V] == views_i[k], so per-view features satisfy F_j[(v+s)%V] == F_i[v].
- Pair cost, squared L2 over all views::

      C_ij(theta) = sum_v || F_i[v] - F_j[(v+theta)%V] ||^2            (so C_ij(s) == 0 above)
                  = ||F_i||^2 + ||F_j||^2 - 2 sum_v <F_i[v], F_j[(v+theta)%V]>

  Mirror: C_ji(theta) = C_ij(-theta).
- Labels: x_i in 0..V-1 is shape i's rotation offset in steps relative to a common frame. Pairwise term of
  labels (t1, t2) of shapes (i, j): D_ij(t1,t2) = C_ij(t2 - t1), W_ij(t1,t2) = exp(-D_ij(t1,t2)/sigma).
  Aligned view k of shape i is original view (k + x_i) % V; to align the mesh rotate it by -x_i steps.
- MRF energy (maximized, see corr_core.mrf): E(x) = sum_i U[i,x_i] + sum_{i<j} W_ij(x_i, x_j).

``pair_costs`` computes the correlation term for all pairs and all thetas at once in the Fourier domain along
the view axis: a real DFT (one small matmul), then for each of the V//2+1 frequencies one complex product
conj(A_k) B_k^T done as a single real float32 GEMM (a, 2D) x (2D, 2b), i.e. 8 * (V//2+1) * a * b * D flops
instead of 2 * V^2 * a * b * D for the Gram matrix of all views (7x fewer for V=16), then an inverse rFFT of
the small (V//2+1, a, b) result. (numpy's complex64 batched matmul was 2-4x slower than these real GEMMs.)
"""
from __future__ import annotations

import numpy as np

from corr_core.mrf import DensePairwise

__all__ = [
    "pair_costs",
    "pair_costs_naive",
    "mirror_pair_costs",
    "auto_sigma",
    "nearest_shapes",
    "neighbor_graph",
    "CirculantPairwise",
    "dense_pairwise",
    "uniform_unary",
    "pair_costs_flops",
]


def _check_features(F: np.ndarray, name: str) -> np.ndarray:
    F = np.asarray(F)
    if F.ndim != 3:
        raise ValueError(f"{name} must have shape (count, V, D), got {F.shape}")
    return F


def pair_costs(FA: np.ndarray, FB: np.ndarray | None = None) -> np.ndarray:
    """C: (a, b, V) float32, C[i, j, theta] = sum_v ||FA[i, v] - FB[j, (v+theta)%V]||^2.

    FA: (a, V, D), FB: (b, V, D) float (FB=None means FB=FA). Computed in float32 (one real GEMM per frequency
    of a real DFT along the view axis, see module docstring); tiny negative values from cancellation are
    clipped to 0.
    """
    FA = _check_features(FA, "FA")
    same = FB is None
    FB = FA if same else _check_features(FB, "FB")
    if FA.shape[1:] != FB.shape[1:]:
        raise ValueError(f"FA {FA.shape} and FB {FB.shape} must share (V, D)")
    V = FA.shape[1]
    FA = FA.astype(np.float32, copy=False)
    FB = FB.astype(np.float32, copy=False)
    A_re, A_im = _real_dft(FA)
    B_re, B_im = (A_re, A_im) if same else _real_dft(FB)
    a, b = FA.shape[0], FB.shape[0]
    P = np.empty((A_re.shape[0], a, b), dtype=np.complex64)
    for k in range(A_re.shape[0]):  # V//2+1 frequencies, one real GEMM (a, 2D) x (2D, 2b) each
        # conj(A) B = (Ar.Br + Ai.Bi) + i (Ar.Bi - Ai.Br)
        D = B_re.shape[2]
        Y = np.empty((2 * b, 2 * D), dtype=np.float32)  # [[Br, Bi], [Bi, -Br]]
        Y[:b, :D], Y[:b, D:], Y[b:, :D] = B_re[k], B_im[k], B_im[k]
        np.negative(B_re[k], out=Y[b:, D:])
        X = Y[:b] if same else np.concatenate([A_re[k], A_im[k]], axis=1)
        Z = X @ Y.T
        P[k].real = Z[:, :b]
        P[k].imag = Z[:, b:]
    # inverse real DFT over k: circular cross-correlation sum_v <FA[i,v], FB[j,v+theta]>
    cross = np.fft.irfft(P, n=V, axis=0).astype(np.float32)  # (V, a, b)
    sq_a = np.einsum("ivd,ivd->i", FA, FA, dtype=np.float64).astype(np.float32)
    sq_b = sq_a if same else np.einsum("jvd,jvd->j", FB, FB, dtype=np.float64).astype(np.float32)
    C = sq_a[:, None, None] + sq_b[None, :, None] - 2.0 * cross.transpose(1, 2, 0)
    return np.maximum(C, 0.0, out=C)


def _real_dft(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real and imaginary parts of the rFFT of F: (n, V, D) along the view axis, each (V//2+1, n, D) float32,
    computed as one small real matmul with the DFT matrix (contiguous output, no strided FFT)."""
    n, V, D = F.shape
    K = V // 2 + 1
    angles = 2.0 * np.pi * np.outer(np.arange(K), np.arange(V)) / V
    T = np.concatenate([np.cos(angles), -np.sin(angles)]).astype(np.float32)  # (2K, V)
    out = (T @ F.transpose(1, 0, 2).reshape(V, n * D)).reshape(2 * K, n, D)
    return out[:K], out[K:]


def pair_costs_flops(a: int, b: int, V: int, D: int) -> float:
    """Floating-point operations of the GEMM part of ``pair_costs``: V//2+1 real GEMMs (a, 2D) x (2D, 2b)."""
    return 8.0 * (V // 2 + 1) * a * b * D


def pair_costs_naive(FA: np.ndarray, FB: np.ndarray | None = None) -> np.ndarray:
    """Reference for ``pair_costs``: explicit loops over pairs and thetas (float64 accumulate): (a, b, V)."""
    FA = _check_features(FA, "FA").astype(np.float64)
    FB = FA if FB is None else _check_features(FB, "FB").astype(np.float64)
    a, V, _ = FA.shape
    b = FB.shape[0]
    C = np.empty((a, b, V), dtype=np.float64)
    for i in range(a):
        for j in range(b):
            for theta in range(V):
                C[i, j, theta] = np.sum((FA[i] - np.roll(FB[j], -theta, axis=0)) ** 2)
    return C.astype(np.float32)


def mirror_pair_costs(C_ab: np.ndarray) -> np.ndarray:
    """C_ba: (b, a, V) from C_ab: (a, b, V), using C_ji(theta) = C_ij(-theta)."""
    C_ab = np.asarray(C_ab)
    V = C_ab.shape[2]
    return C_ab.transpose(1, 0, 2)[:, :, (-np.arange(V)) % V]


def auto_sigma(C: np.ndarray) -> float:
    """Default kernel width: median over pairs i<j of min_theta C_ij(theta).

    Rationale: exp(-C/sigma) is then ~1/e for a typical best-aligned pair, so good alignments are
    distinguishable from bad ones without the kernel collapsing to the single nearest pair. Falls back to the
    mean of positive values, then 1.0, if the median is not positive (e.g. duplicated shapes).
    """
    C = np.asarray(C)
    N = C.shape[0]
    if N < 2:
        return 1.0
    best = C.min(axis=2).astype(np.float64)[np.triu_indices(N, 1)]
    sigma = float(np.median(best))
    if sigma > 0:
        return sigma
    positive = best[best > 0]
    return float(positive.mean()) if positive.size else 1.0


def nearest_shapes(C: np.ndarray, k: int) -> np.ndarray:
    """(N, k) int: for each shape the k other shapes with smallest min_theta C_ij (ties by index)."""
    C = np.asarray(C)
    N = C.shape[0]
    k = min(k, N - 1)
    best = C.min(axis=2).astype(np.float64)
    best[np.arange(N), np.arange(N)] = np.inf
    return np.argsort(best, axis=1, kind="stable")[:, :k]


def _neighbor_mask(N: int, neighbors: np.ndarray | None) -> np.ndarray:
    mask = np.ones((N, N), dtype=bool)
    if neighbors is not None:
        neighbors = np.asarray(neighbors, dtype=np.int64)
        mask = np.zeros((N, N), dtype=bool)
        mask[np.repeat(np.arange(N), neighbors.shape[1]), neighbors.ravel()] = True
        mask |= mask.T
    mask[np.arange(N), np.arange(N)] = False
    return mask


def _symmetrize_costs(C: np.ndarray) -> np.ndarray:
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


def _rows_per_block(N: int, V: int, budget_bytes: int = 32 << 20) -> int:
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
    def from_kernel(cls, K: np.ndarray) -> "CirculantPairwise":
        """Operator with W[i,j,a,b] = K[i,j,(b-a)%V] for any real K: (N,N,V) with K[j,i,t] == K[i,j,-t];
        the diagonal is zeroed. Dense storage (float32 if K is float32, else float64)."""
        self = cls.__new__(cls)
        K = np.array(K, dtype=np.float32 if np.asarray(K).dtype == np.float32 else np.float64, copy=True)
        K[np.arange(K.shape[0]), np.arange(K.shape[0])] = 0.0
        self._init_dense(K)
        self.sigma = float("nan")
        return self

    @classmethod
    def from_edges(cls, indptr: np.ndarray, indices: np.ndarray, K_edges: np.ndarray) -> "CirculantPairwise":
        """Sparse operator from a symmetric CSR graph (indptr (N+1,), indices (E,)) and per-edge kernels
        K_edges: (E, V) with K_edges[e(j,i)] == K_edges[e(i,j)][-t] (not checked)."""
        self = cls.__new__(cls)
        self._init_sparse(np.asarray(indptr, np.int64), np.asarray(indices, np.int64), np.asarray(K_edges),
                          len(indptr) - 1)
        self.sigma = float("nan")
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

    def harmonic(self, h: int = 1):
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


def uniform_unary(n: int, V: int, seed: int | None = 0) -> np.ndarray:
    """(n, V) i.i.d. uniform [0, 1) unary terms (they break the global-rotation tie of the pairwise term)."""
    return np.random.default_rng(seed).uniform(0.0, 1.0, size=(n, V))
