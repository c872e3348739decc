"""Continuous azimuths from the sampled rotation costs C_ij(theta) (theta in view steps, see
``corr_core.alignment.pair_costs`` for the conventions).

C_ij is sampled at V whole view steps, but as a function of the rotation it is smooth; its trigonometric
(band-limited) interpolation through the V samples, the inverse real DFT evaluated between the samples, gives a
continuous relative rotation d_ij = argmin_phi C_ij(phi) per pair. The continuous labels t: (N,) float steps
are then the weighted least-squares solution of t_j - t_i ~= d_ij over the pairs that agree with the discrete
labels to within one view (a graph-Laplacian system; the others are outliers for this shape). Shapes with a
rotational symmetry of order k are defined modulo V/k steps: their pairs are unwrapped modulo that period.
"""
from __future__ import annotations

import numpy as np

__all__ = ["interpolate_costs", "continuous_argmin", "refine_labels", "steps_to_degrees"]


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


def _evaluate(c: np.ndarray, phi: np.ndarray, V: int, derivative: int = 0) -> np.ndarray:
    """Band-limited values (or their ``derivative``-th derivative in phi) of spectra c (..., K) at phi (..., m)."""
    k = np.arange(c.shape[-1])
    w = 2j * np.pi * k / V
    e = np.exp(w * phi[..., None]) * w ** derivative  # (..., m, K)
    if V % 2 == 0 and derivative == 0:  # Nyquist: cos, not exp (a real interpolant with no sine term)
        e[..., -1] = np.cos(np.pi * phi)
    elif V % 2 == 0:
        e[..., -1] = np.real(((1j * np.pi) ** derivative) * np.exp(1j * np.pi * phi))
    return np.real(np.einsum("...mk,...k->...m", e, c))


def interpolate_costs(C: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """C: (..., V) samples at theta = 0..V-1, phi: (..., m) float steps -> (..., m) float64 band-limited values
    (equal to C at whole steps)."""
    C = np.asarray(C)
    return _evaluate(_spectrum(C), np.asarray(phi, dtype=np.float64), C.shape[-1])


def continuous_argmin(C: np.ndarray, grid: int = 40, newton_steps: int = 3) -> np.ndarray:
    """(...,) float steps in [0, V): the minimiser of the band-limited interpolation of C (..., V) within one
    step of its smallest sample (a grid of ``grid`` points per step, then Newton steps kept inside the bracket).
    Ties between equal samples go to the first one (np.argmin), so the result is deterministic."""
    C = np.asarray(C)
    V = C.shape[-1]
    c = _spectrum(C)
    m = np.argmin(C, axis=-1).astype(np.float64)
    offsets = np.linspace(-1.0, 1.0, 2 * grid + 1)
    phi = m[..., None] + offsets
    best = phi[..., 0] * 0 + np.take_along_axis(phi, np.argmin(_evaluate(c, phi, V), -1)[..., None], -1)[..., 0]
    for _ in range(newton_steps):
        g = _evaluate(c, best[..., None], V, 1)[..., 0]
        h = _evaluate(c, best[..., None], V, 2)[..., 0]
        step = np.where(h > 0, -g / np.where(h > 0, h, 1.0), 0.0)
        best = np.clip(best + np.clip(step, -0.5 / grid, 0.5 / grid), m - 1.0, m + 1.0)
    return np.mod(best, V)


def _wrap(x: np.ndarray, period: np.ndarray | float) -> np.ndarray:
    """x wrapped to [-period/2, period/2)."""
    return (x + 0.5 * period) % period - 0.5 * period


def refine_labels(C: np.ndarray, labels: np.ndarray, sigma: float, periods: np.ndarray | None = None,
                  tolerance: float = 1.0) -> np.ndarray:
    """Continuous labels t: (N,) float steps, near the discrete ``labels`` (N,) int, from pair costs C (N, N, V).

    Pair (i, j), i < j: d_ij = continuous_argmin C_ij, weight exp(-min C_ij / sigma); the pair counts only when
    d_ij is within ``tolerance`` steps of labels_j - labels_i modulo the pair's period
    p_ij = min(periods_i, periods_j) (V for asymmetric shapes, V/k for a k-fold symmetric one, 0 for a fully
    symmetric one: its pairs are left out). Weighted least squares of t_j - t_i = d_ij (unwrapped near the
    labels), with the gauge sum_i (t_i - labels_i) = 0 per connected part, so round(t) ~= labels.
    A shape with no usable pair keeps its label.
    """
    C = np.asarray(C)
    N, _, V = C.shape
    x = np.asarray(labels, dtype=np.float64)
    per = np.full(N, float(V)) if periods is None else np.asarray(periods, dtype=np.float64)
    iu, ju = np.triu_indices(N, 1)
    Cp = C[iu, ju]                                                   # (P, V)
    d = continuous_argmin(Cp)
    p = np.minimum(per[iu], per[ju])
    usable = p > 0
    p_safe = np.where(usable, p, V)
    residual = _wrap(d - (x[ju] - x[iu]), p_safe)                     # continuous minus discrete, (P,)
    w = np.exp(-Cp.min(axis=1) / sigma) * usable * (np.abs(residual) <= tolerance)
    # weighted least squares of delta_j - delta_i = residual with t = x + delta
    L = np.zeros((N, N))
    b = np.zeros(N)
    np.add.at(L, (iu, iu), w)
    np.add.at(L, (ju, ju), w)
    np.add.at(L, (iu, ju), -w)
    np.add.at(L, (ju, iu), -w)
    np.add.at(b, ju, w * residual)
    np.add.at(b, iu, -w * residual)
    L += np.full((N, N), 1.0 / N) * (L.diagonal().max() if N else 1.0) * 1e-9  # tiny gauge term, well-posed
    delta = np.linalg.lstsq(L, b, rcond=None)[0]
    delta -= delta.mean()
    delta[L.diagonal() <= 1e-6 * max(L.diagonal().max(), 1e-300)] = 0.0
    return x + delta


def steps_to_degrees(t: np.ndarray, V: int) -> np.ndarray:
    """(n,) float degrees in [0, 360) of continuous labels t (n,) in view steps."""
    return np.mod(np.asarray(t, dtype=np.float64) * 360.0 / V, 360.0)
