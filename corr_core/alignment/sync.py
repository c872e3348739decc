"""Joint rotation alignment by synchronization: stronger peers of the LH MRF solver on the same C_ij.

Conventions as in corr_core.alignment.pair_costs: C: (N, N, V) with C_ij(theta) = sum_v ||F_i[v] - F_j[(v+theta)%V]||^2,
labels x in 0..V-1 with x_j - x_i ~= argmin_theta C_ij(theta) for consistent pairs; K_ij = exp(-C_ij/sigma).

- ``spectral_sync``: angular synchronization (Singer 2011). H_ij = sum_theta K_ij(theta) exp(+i 2 pi theta/V)
  (the first Fourier coefficient of the kernel, Hermitian because C_ji(theta) = C_ij(-theta)); for consistent
  data H_ij ~ w_ij z_i conj(z_j) with z_i = exp(-i 2 pi x_i / V), so the top eigenvector's phases give
  x_i = round(-angle(z_i) V / (2 pi) - delta) mod V (up to one global offset; delta removes the eigenvector's
  arbitrary global phase, see ``round_phases``).
- ``projected_power``: Chen & Candes' projected power method ("The projected power method: an efficient
  algorithm for joint alignment from pairwise differences", CPAM 2018), hard (mu -> infinity) version:
  z <- onehot(argmax_a (S z)_a) per node, all nodes at once, S_ij(a,b) = score_ij((b-a)%V) with the per-pair
  mean over theta removed (their debiasing), started from ``spectral_sync``.
"""
from __future__ import annotations

import numpy as np

from corr_core.alignment.circulant import CirculantPairwise, symmetrize_costs
from corr_core.alignment.pair_costs import auto_sigma

__all__ = ["sync_matrix", "spectral_sync", "spectral_sync_operator", "round_phases", "projected_power",
           "projected_power_operator", "top_eigenvector"]


def sync_matrix(C: np.ndarray, sigma: float | None = None, neighbors: np.ndarray | None = None,
                *, harmonic: int = 1) -> np.ndarray:
    """H: (N, N) complex128 Hermitian, H_ij = sum_theta exp(-C_ij(theta)/sigma) exp(i 2 pi harmonic theta/V),
    zero diagonal (and zero off the optional neighbour graph, see CirculantPairwise). sigma=None: auto_sigma.
    Always a dense ndarray (see ``CirculantPairwise.harmonic`` for the sparse form)."""
    if sigma is None:
        sigma = auto_sigma(C)
    H = CirculantPairwise(C, sigma, neighbors).harmonic(h=harmonic)
    return H.toarray() if hasattr(H, "toarray") else H


# below this many shapes a dense eigensolve (exact, as before); above, Lanczos for the top eigenvector only
DENSE_EIGH_MAX = 500


def top_eigenvector(H) -> np.ndarray:
    """Eigenvector of the largest eigenvalue of a Hermitian (N, N) matrix (ndarray or scipy.sparse)."""
    N = H.shape[0]
    if N <= DENSE_EIGH_MAX:
        dense = H.toarray() if hasattr(H, "toarray") else H
        return np.linalg.eigh(dense)[1][:, -1]
    from scipy.sparse.linalg import eigsh
    v0 = np.full(N, 1.0 / np.sqrt(N), dtype=np.complex128)
    return eigsh(H, k=1, which="LA", v0=v0, tol=1e-10)[1][:, 0]


def spectral_sync_operator(op: CirculantPairwise, normalize: bool = True) -> np.ndarray:
    """Labels (N,) int from a built CirculantPairwise (dense or kNN-sparse): the top eigenvector of its first
    harmonic H (``op.harmonic(h=1)``), degree-normalized if ``normalize``. Lets a caller that already holds the
    operator (e.g. for energies) avoid building the kernel twice."""
    H = op.harmonic(h=1)
    if normalize:
        deg = np.asarray(abs(H).sum(axis=1)).ravel()
        s = 1.0 / np.sqrt(np.where(deg > 0, deg, 1.0))
        if hasattr(H, "toarray"):
            import scipy.sparse as sp
            D = sp.diags(s)
            H = (D @ H @ D).tocsr()
        else:
            H *= s[:, None]
            H *= s[None, :]
    return round_phases(top_eigenvector(H), op.n_labels)


def spectral_sync(C: np.ndarray, sigma: float | None = None, neighbors: np.ndarray | None = None,
                  normalize: bool = True) -> np.ndarray:
    """Labels (N,) int in 0..V-1 from the top eigenvector of ``sync_matrix`` (Singer 2011), correct up to one
    global offset. normalize=True uses the degree-normalized matrix D^-1/2 H D^-1/2, D_ii = sum_j |H_ij|
    (Singer & Shkolnisky's variant, less dominated by a few high-degree shapes). With ``neighbors`` H is
    sparse (kNN graph). N > DENSE_EIGH_MAX uses Lanczos (scipy eigsh) instead of a full eigensolve."""
    if sigma is None:
        sigma = auto_sigma(C)
    return spectral_sync_operator(CirculantPairwise(C, sigma, neighbors), normalize)


def round_phases(z: np.ndarray, V: int) -> np.ndarray:
    """Labels (N,) int from complex z_i ~ exp(-i 2 pi x_i / V) (any common phase factor): continuous labels
    t_i = -angle(z_i) V / (2 pi); the eigenvector's arbitrary global phase is first removed by subtracting the
    circular mean of the fractional parts of t (so rounding cuts between steps, not through them)."""
    t = -np.angle(z) * V / (2 * np.pi)
    frac_shift = np.angle(np.mean(np.exp(2j * np.pi * t))) / (2 * np.pi)
    return np.rint(t - frac_shift).astype(np.int64) % V


def projected_power(C: np.ndarray, sigma: float | None = None, labels0: np.ndarray | None = None,
                    score: str = "kernel", *, max_iter: int = 100,
                    neighbors: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Chen & Candes projected power method (hard projection) on the pairwise scores; returns
    (labels (N,) int, iterations). score="kernel": exp(-C/sigma) (robust to outlier pairs: bounded);
    score="log": -C/sigma (Gaussian log-likelihood). Each pair's score is centered over theta.
    labels0=None: start from spectral_sync(C, sigma)."""
    if sigma is None:
        sigma = auto_sigma(C)
    if score not in ("kernel", "log"):
        raise ValueError(f"score must be 'kernel' or 'log', got {score!r}")
    op = _centered_score_operator(C, sigma, score, neighbors)
    labels = spectral_sync(C, sigma, neighbors) if labels0 is None else np.asarray(labels0, np.int64) % op.n_labels
    return projected_power_operator(op, labels, max_iter=max_iter)


def projected_power_operator(op: CirculantPairwise, labels0: np.ndarray, *,
                             max_iter: int = 100) -> tuple[np.ndarray, int]:
    """The hard projected power iteration z <- onehot(argmax_a (S z)_a) from labels0 (N,) int on a built score
    operator S (``CirculantPairwise``, dense or sparse; e.g. centred kernels): (labels (N,) int, iterations)."""
    N, V = op.n_nodes, op.n_labels
    labels = np.asarray(labels0, np.int64) % V
    it = 0
    for it in range(1, max_iter + 1):
        Z = np.zeros((N, V))
        Z[np.arange(N), labels] = 1.0
        new = np.argmax(op.matvec(Z), axis=1)
        if np.array_equal(new, labels):
            break
        labels = new
    return labels, it


def _centered_score_operator(C: np.ndarray, sigma: float, score: str, neighbors) -> CirculantPairwise:
    """Operator of the per-pair scores (kernel exp(-C/sigma) or log -C/sigma), each centred over theta, on
    the complete graph (dense) or the kNN graph (sparse, same CSR layout as CirculantPairwise)."""
    base = CirculantPairwise(C, sigma, neighbors)
    if base.sparse:
        if score == "kernel":
            S = base.K_edges.astype(np.float64)
        else:
            rows = np.repeat(np.arange(base.n_nodes), np.diff(base.indptr))
            V = base.n_labels
            S = -0.5 * (np.asarray(C)[rows, base.indices].astype(np.float64)
                        + np.asarray(C)[base.indices, rows][:, (-np.arange(V)) % V]) / sigma
        return CirculantPairwise.from_edges(base.indptr, base.indices, S - S.mean(axis=1, keepdims=True))
    if score == "kernel":
        S = base.K
        S -= S.mean(axis=2, keepdims=True, dtype=np.float64).astype(S.dtype)
        return CirculantPairwise.from_kernel(S, sigma=sigma, copy=False)  # S is a fresh array: no copy
    del base
    S = -symmetrize_costs(C) / sigma
    return CirculantPairwise.from_kernel(S - S.mean(axis=2, keepdims=True))
