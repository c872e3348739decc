"""Continuous azimuths from the sampled rotation costs C_ij(theta) (theta in view steps, see
``corr_core.alignment.pair_costs`` for the conventions).

C_ij is sampled at V whole view steps, but as a function of the rotation it is smooth; its trigonometric
(band-limited) interpolation through the V samples, the inverse real DFT evaluated between the samples, gives a
continuous relative rotation d_ij = argmin_phi C_ij(phi) per pair. The continuous labels t: (N,) float steps
are then the weighted least-squares solution of t_j - t_i ~= d_ij over the pairs that agree with the discrete
labels to within one view (a graph-Laplacian system; the others are outliers for this pair). Shapes with a
rotational symmetry of order k are defined modulo V/k steps: their pairs are unwrapped modulo that period.
"""
from __future__ import annotations

import numpy as np

__all__ = ["interpolate_costs", "continuous_argmin", "refine_labels", "refine_labels_graph", "steps_to_degrees"]


def _spectrum(C: np.ndarray) -> np.ndarray:
    """(..., V//2+1) complex: the trigonometric-interpolation coefficients of C (..., V) along the last axis,
    doubled except for the mean (and the Nyquist term of an even V), so that
    value(phi) = Re(sum_k c_k exp(2 pi i k phi / V))."""
    V = C.shape[-1]
    c = np.fft.rfft(np.asarray(C, dtype=np.float64), axis=-1) / V
    c[..., 1:] *= 2.0
    if V % 2 == 0:
        c[..., -1] /= 2.0  # Nyquist: c cos(pi phi), the symmetric choice
    return c


def _evaluate(c: np.ndarray, phi: np.ndarray, V: int, *, derivative: int = 0) -> np.ndarray:
    """Band-limited values (or their ``derivative``-th derivative in phi) of spectra c (..., K) at phi (..., m):
    Re sum_k c_k (i w_k)^derivative exp(i w_k phi), w_k = 2 pi k / V (the Nyquist coefficient is real, so its
    term is c cos(pi phi), the symmetric choice)."""
    w = 2j * np.pi * np.arange(c.shape[-1]) / V
    e = np.exp(w * phi[..., None]) * w ** derivative  # (..., m, K)
    return np.real(np.einsum("...mk,...k->...m", e, c))


def interpolate_costs(C: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """C: (..., V) samples at theta = 0..V-1, phi: (..., m) float steps -> (..., m) float64 band-limited values
    (equal to C at whole steps)."""
    C = np.asarray(C)
    return _evaluate(_spectrum(C), np.asarray(phi, dtype=np.float64), C.shape[-1])


def _fine_grid(c: np.ndarray, V: int, samples_per_step: int) -> np.ndarray:
    """(..., V * samples_per_step) band-limited values at phi = j / samples_per_step: one zero-padded inverse
    real FFT of the spectra c (..., K)."""
    n = V * samples_per_step
    X = np.zeros(c.shape[:-1] + (n // 2 + 1,), dtype=np.complex128)
    X[..., 0] = c[..., 0] * n
    X[..., 1:c.shape[-1]] = c[..., 1:] * (n / 2)
    return np.fft.irfft(X, n=n, axis=-1)


def _slopes(c: np.ndarray, phi: np.ndarray, V: int) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives (...,) of the band-limited function of spectra c (..., K) at phi (...,)."""
    K = c.shape[-1]
    z = np.exp(2j * np.pi * phi / V)
    powers = np.cumprod(np.concatenate([np.ones(phi.shape + (1,), complex),
                                        np.repeat(z[..., None], K - 1, axis=-1)], axis=-1), axis=-1)  # z^k
    w = 2j * np.pi * np.arange(K) / V
    cz = c * powers
    return np.real(cz @ w), np.real(cz @ (w * w))


def continuous_argmin(C: np.ndarray, *, samples_per_step: int = 8, newton_steps: int = 3) -> np.ndarray:
    """(...,) float steps in [0, V): the minimiser of the band-limited interpolation of C (..., V): the smallest
    value on a grid of ``samples_per_step`` points per step (``_fine_grid``), then Newton steps kept within half
    a grid cell. Ties go to the first grid point, so the result is deterministic."""
    C = np.asarray(C)
    V = C.shape[-1]
    c = _spectrum(C)
    start = np.argmin(_fine_grid(c, V, samples_per_step), axis=-1) / samples_per_step
    best = start.copy()
    half_cell = 0.5 / samples_per_step
    for _ in range(newton_steps):
        g, h = _slopes(c, best, V)
        step = np.where(h > 0, -g / np.where(h > 0, h, 1.0), 0.0)
        best = np.clip(best + step, start - half_cell, start + half_cell)
    return np.mod(best, V)


def _wrap(x: np.ndarray, period: np.ndarray | float) -> np.ndarray:
    """x wrapped to [-period/2, period/2)."""
    return (x + 0.5 * period) % period - 0.5 * period


def _pair_minima(C: np.ndarray, iu: np.ndarray, ju: np.ndarray, chunk: int) -> tuple[np.ndarray, np.ndarray]:
    """(d, cmin): continuous argmin (P,) float and smallest sample (P,) of C[iu, ju] (P pairs), ``chunk`` pairs
    at a time (bounded memory for large collections)."""
    d = np.empty(len(iu))
    cmin = np.empty(len(iu))
    for s in range(0, len(iu), chunk):
        block = np.asarray(C[iu[s:s + chunk], ju[s:s + chunk]], dtype=np.float64)
        d[s:s + chunk] = continuous_argmin(block)
        cmin[s:s + chunk] = block.min(axis=1)
    return d, cmin


def _pair_weights(x: np.ndarray, iu: np.ndarray, ju: np.ndarray, d: np.ndarray, cmin: np.ndarray, V: int,
                  sigma: float, periods: np.ndarray | None, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """(w, residual) (P,) of pairs (iu, ju) with continuous argmins d and smallest samples cmin (see
    ``refine_labels``): residual = d - (x_j - x_i) wrapped modulo the pair's period, w = exp(-cmin/sigma) for a
    usable pair within ``tolerance`` steps, else 0."""
    per = np.full(len(x), float(V)) if periods is None else np.asarray(periods, dtype=np.float64)
    p = np.minimum(per[iu], per[ju])
    usable = p > 0
    residual = _wrap(d - (x[ju] - x[iu]), np.where(usable, p, V))    # continuous minus discrete, (P,)
    w = np.exp(-cmin / sigma) * usable * (np.abs(residual) <= tolerance)
    return w, residual


def refine_labels_graph(N: int, rows: np.ndarray, cols: np.ndarray, costs: np.ndarray, labels: np.ndarray,
                        sigma: float, periods: np.ndarray | None = None, *, tolerance: float = 1.0,
                        chunk: int = 16384) -> np.ndarray:
    """``refine_labels`` on a candidate graph: the pairs (rows[p], cols[p]) (P,), rows < cols, with costs
    (P, V) instead of all pairs of a dense C. The weighted graph Laplacian is sparse and the system is solved
    by conjugate gradients (Jacobi preconditioned, x0 = 0, relative tolerance 1e-10; deterministic): memory
    O(N + P), no N x N matrix. Returns t: (N,) float steps."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components
    from scipy.sparse.linalg import cg

    costs = np.asarray(costs)
    V = costs.shape[1]
    x = np.asarray(labels, dtype=np.float64)
    iu, ju = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
    d, cmin = np.empty(len(iu)), np.empty(len(iu))
    for s in range(0, len(iu), chunk):
        block = costs[s:s + chunk].astype(np.float64)
        d[s:s + chunk] = continuous_argmin(block)
        cmin[s:s + chunk] = block.min(axis=1)
    w, residual = _pair_weights(x, iu, ju, d, cmin, V, sigma, periods, tolerance)
    on = w > 0  # the graph of usable pairs (no explicit zeros: they would count as edges)
    A = sp.coo_matrix((np.concatenate([-w[on], -w[on]]), (np.concatenate([iu[on], ju[on]]),
                                                         np.concatenate([ju[on], iu[on]]))), shape=(N, N)).tocsr()
    degree = -np.asarray(A.sum(axis=1)).ravel()
    b = np.zeros(N)
    np.add.at(b, ju, w * residual)
    np.add.at(b, iu, -w * residual)
    ridge = 1e-8 * max(degree.max(initial=0.0), 1e-300)
    L = (A + sp.diags(degree + ridge)).tocsr()
    M = sp.diags(1.0 / (degree + ridge))
    delta, info = cg(L, b, x0=np.zeros(N), rtol=1e-10, atol=0.0, maxiter=20 * N + 100, M=M)
    if info != 0:
        raise RuntimeError(f"continuous refinement: conjugate gradients did not converge ({info} iterations)")
    # the gauge (sum delta = 0 on each connected part) is only loosely held by the ridge under the
    # preconditioner: set it exactly
    _, part = connected_components(A, directed=False)
    delta -= (np.bincount(part, weights=delta) / np.bincount(part))[part]
    return x + delta


def refine_labels(C: np.ndarray, labels: np.ndarray, sigma: float, periods: np.ndarray | None = None,
                  *, tolerance: float = 1.0, chunk: int = 16384) -> np.ndarray:
    """Continuous labels t: (N,) float steps, near the discrete ``labels`` (N,) int, from pair costs C (N, N, V).

    Pair (i, j), i < j: d_ij = continuous_argmin C_ij, weight exp(-min C_ij / sigma); the pair counts only when
    d_ij is within ``tolerance`` steps of labels_j - labels_i modulo the pair's period
    p_ij = min(periods_i, periods_j) (V for asymmetric shapes, V/k for a k-fold symmetric one, 0 for a fully
    symmetric one: its pairs are left out). t = labels + delta with delta the weighted least-squares solution
    of delta_j - delta_i = d_ij - (labels_j - labels_i) (unwrapped near 0), gauge sum delta = 0 over each
    connected part of the graph of usable pairs, so round(t) ~= labels. A shape with no usable pair keeps its
    label.
    """
    C = np.asarray(C)
    N, _, V = C.shape
    x = np.asarray(labels, dtype=np.float64)
    iu, ju = np.triu_indices(N, 1)
    d, cmin = _pair_minima(C, iu, ju, chunk)
    w, residual = _pair_weights(x, iu, ju, d, cmin, V, sigma, periods, tolerance)
    L = np.zeros((N, N))                                               # weighted graph Laplacian
    np.add.at(L, (iu, ju), -w)
    L += L.T
    np.fill_diagonal(L, -L.sum(axis=1))
    b = np.zeros(N)
    np.add.at(b, ju, w * residual)
    np.add.at(b, iu, -w * residual)
    # a tiny ridge: in each connected part of the graph b sums to 0, so the solution has sum(delta) = 0 there
    # (the gauge), and a shape with no usable pair gets delta = 0
    ridge = 1e-8 * max(L.diagonal().max(), 1e-300)
    delta = np.linalg.solve(L + ridge * np.eye(N), b)
    return x + delta


def steps_to_degrees(t: np.ndarray, V: int) -> np.ndarray:
    """(n,) float degrees in [0, 360) of continuous labels t (n,) in view steps."""
    return np.mod(np.asarray(t, dtype=np.float64) * 360.0 / V, 360.0)
