"""Rotation costs C_ij(theta) between shapes seen from V azimuths, and what is read off them directly.

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
- MRF energy (maximized, see corr_core.mrf): E(x) = sum_i U[i,x_i] + sum_{i<j} W_ij(x_i, x_j); its pairwise
  operator is ``corr_core.alignment.circulant.CirculantPairwise``, the solvers are in
  ``corr_core.alignment.solvers``.

``pair_costs`` computes the correlation term for all pairs and all thetas at once in the Fourier domain along
the view axis: a real DFT (one small matmul), then for each of the V//2+1 frequencies one complex product
conj(A_k) B_k^T done as a single real float32 GEMM (a, 2D) x (2D, 2b), i.e. 8 * (V//2+1) * a * b * D flops
instead of 2 * V^2 * a * b * D for the Gram matrix of all views (7x fewer for V=16), then an inverse rFFT of
the small (V//2+1, a, b) result. (numpy's complex64 batched matmul was 2-4x slower than these real GEMMs.)
"""
from __future__ import annotations

import numpy as np

__all__ = ["pair_costs", "pair_costs_listed", "pair_costs_naive", "pair_costs_flops", "mirror_pair_costs", "shift_costs", "auto_sigma",
           "nearest_shapes"]


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


# above this fraction of listed pairs in an (a, b) block, ``pair_costs_listed`` computes the whole block with
# GEMMs and picks the listed pairs (cheaper than gathering the pairs one by one)
DENSE_BLOCK_FRACTION = 0.25


def pair_costs_listed(FA: np.ndarray, FB: np.ndarray, pairs: np.ndarray, *, chunk: int = 128) -> np.ndarray:
    """C: (p, V) float32, C[k, theta] = sum_v ||FA[i, v] - FB[j, (v+theta)%V]||^2 for the listed pairs
    (i, j) = pairs[k] (p, 2) int (row of FA, row of FB): the values of ``pair_costs(FA, FB)[i, j]`` without the
    other a*b - p pairs (same Fourier-domain formula, per pair: 8 (V//2+1) D flops each, gathered ``chunk``
    pairs at a time; a block with more than DENSE_BLOCK_FRACTION of its pairs listed is computed whole)."""
    FA, FB = _check_features(FA, "FA"), _check_features(FB, "FB")
    if FA.shape[1:] != FB.shape[1:]:
        raise ValueError(f"FA {FA.shape} and FB {FB.shape} must share (V, D)")
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if len(pairs) and (pairs.min() < 0 or pairs[:, 0].max() >= len(FA) or pairs[:, 1].max() >= len(FB)):
        raise ValueError(f"pairs index rows outside FA ({len(FA)}) or FB ({len(FB)})")
    if len(pairs) > DENSE_BLOCK_FRACTION * len(FA) * len(FB):
        return np.ascontiguousarray(pair_costs(FA, FB)[pairs[:, 0], pairs[:, 1]])
    V = FA.shape[1]
    FA = FA.astype(np.float32, copy=False)
    FB = FB.astype(np.float32, copy=False)
    A_re, A_im = _real_dft_blocks(FA)
    B_re, B_im = _real_dft_blocks(FB)
    P = np.empty((A_re.shape[0], len(pairs)), dtype=np.complex64)
    for s in range(0, len(pairs), chunk):
        i, j = pairs[s:s + chunk, 0], pairs[s:s + chunk, 1]
        Ar, Ai, Br, Bi = A_re[:, i], A_im[:, i], B_re[:, j], B_im[:, j]      # (K, c, D) each
        P[:, s:s + chunk].real = np.einsum("kcd,kcd->kc", Ar, Br) + np.einsum("kcd,kcd->kc", Ai, Bi)
        P[:, s:s + chunk].imag = np.einsum("kcd,kcd->kc", Ar, Bi) - np.einsum("kcd,kcd->kc", Ai, Br)
    cross = np.fft.irfft(P, n=V, axis=0).astype(np.float32)               # (V, p)
    sq_a = np.einsum("ivd,ivd->i", FA, FA, dtype=np.float64).astype(np.float32)
    sq_b = np.einsum("jvd,jvd->j", FB, FB, dtype=np.float64).astype(np.float32)
    C = sq_a[pairs[:, 0], None] + sq_b[pairs[:, 1], None] - 2.0 * cross.T
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


def _real_dft_blocks(F: np.ndarray, *, rows: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """``_real_dft`` computed ``rows`` shapes at a time into the two (V//2+1, n, D) float32 outputs, so that no
    transposed copy of the whole stack F: (n, V, D) is made (a pair task's stacks are hundreds of MB)."""
    n, V, D = F.shape
    K = V // 2 + 1
    re = np.empty((K, n, D), np.float32)
    im = np.empty((K, n, D), np.float32)
    for s in range(0, n, rows):
        re[:, s:s + rows], im[:, s:s + rows] = _real_dft(F[s:s + rows])
    return re, im


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


def shift_costs(C: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """Pair costs (N, N, V) after cyclically shifting shape i's views by shifts[i] (N,) int (as if shape i were
    rotated by +shifts[i] steps): C'_ij(theta) = C_ij(theta + s_i - s_j)."""
    N, _, V = C.shape
    idx = (np.arange(V)[None, None, :] + shifts[:, None, None] - shifts[None, :, None]) % V
    return np.take_along_axis(C, idx, axis=2)
