"""Spectral point descriptors: Heat Kernel Signature (HKS) and Wave Kernel Signature (WKS).

Both are built from the low-frequency Laplace–Beltrami eigenpairs of ``corr_core.geometry.laplacian.eigenpairs``
(M-orthonormal eigenvectors, so eigenvector signs and rotations inside eigenspaces do not matter: only
``phi_k(x)^2`` enters). They are invariant to isometries, hence blind to intrinsic symmetries (left/right).
"""
from __future__ import annotations

import numpy as np

_LOG10_X4 = 4.0 * np.log(10.0)


def _first_positive(evals: np.ndarray) -> int:
    """Index of the first non-zero eigenvalue (skips the constant mode, and a few if the mesh is split)."""
    tol = 1e-8 * max(float(np.max(np.abs(evals))), 1.0)
    idx = np.flatnonzero(evals > tol)
    if len(idx) == 0:
        raise ValueError("all eigenvalues are ~0: no spectral information")
    return int(idx[0])


def hks_times(evals: np.ndarray, *, n_times: int = 16) -> np.ndarray:
    """Sun et al. 2009 time range: ``n_times`` log-spaced times in [4 ln10 / lambda_max, 4 ln10 / lambda_1].

    Returns (n_times,) float, units area (1/eigenvalue units).
    """
    lam1 = evals[_first_positive(evals)]
    return np.geomspace(_LOG10_X4 / evals[-1], _LOG10_X4 / lam1, n_times)


def hks(evals: np.ndarray, evecs: np.ndarray, times: np.ndarray | None = None, *, n_times: int = 16) -> np.ndarray:
    """Scaled Heat Kernel Signature.

    HKS(x, t) = sum_k exp(-lambda_k t) phi_k(x)^2, divided per time by the heat trace
    sum_k exp(-lambda_k t) (the "scaled HKS" of Sun et al. 2009, sec. 5), which removes the dominant
    decay in t so that every time contributes comparably to a Euclidean descriptor distance.

    Args:
        evals: (k,) ascending eigenvalues; evecs: (n,k) M-orthonormal eigenvectors.
        times: (T,) diffusion times (units area); default ``hks_times(evals, n_times=n_times)``.
    Returns:
        (n, T) float descriptor.
    """
    evals = np.asarray(evals, dtype=np.float64)
    t = hks_times(evals, n_times=n_times) if times is None else np.asarray(times, dtype=np.float64)
    heat = np.exp(-np.outer(evals, t))  # (k, T)
    return (np.asarray(evecs, dtype=np.float64) ** 2 @ heat) / heat.sum(axis=0)


def wks(evals: np.ndarray, evecs: np.ndarray, *, n_energies: int = 100, variance: float = 6.0) -> np.ndarray:
    """Wave Kernel Signature (Aubry, Schlickewei, Cremers 2011).

    Log-energies e_j are ``n_energies`` evenly spaced values in [log lambda_1, log lambda_max / 1.02]
    (as in the authors' code); each band is a Gaussian in log-eigenvalue of width
    sigma = variance * (e_2 - e_1):
        WKS(x, e) = sum_k phi_k(x)^2 exp(-(e - log lambda_k)^2 / (2 sigma^2)) / C_e,
        C_e = sum_k exp(-(e - log lambda_k)^2 / (2 sigma^2)).
    The zero eigenvalue(s) are skipped.

    Args:
        evals: (k,) ascending eigenvalues; evecs: (n,k) M-orthonormal eigenvectors.
        n_energies: number of energy bands E; variance: band width in units of the band spacing.
    Returns:
        (n, E) float descriptor.
    """
    evals = np.asarray(evals, dtype=np.float64)
    first = _first_positive(evals)
    log_lam = np.log(evals[first:])
    phi2 = np.asarray(evecs, dtype=np.float64)[:, first:] ** 2
    e = np.linspace(log_lam[0], log_lam[-1] / 1.02 if log_lam[-1] > 0 else log_lam[-1], n_energies)
    sigma = variance * (e[1] - e[0]) if n_energies > 1 else 1.0
    bands = np.exp(-((e[None, :] - log_lam[:, None]) ** 2) / (2 * sigma**2))  # (k, E)
    return (phi2 @ bands) / bands.sum(axis=0)


def normalize_columns(D: np.ndarray, reference: np.ndarray | None = None) -> np.ndarray:
    """Divide each descriptor dimension by its L2 norm over the rows of ``reference`` (default ``D``).

    Args: D: (a,d); reference: (r,d). Returns (a,d). Used to give every time/energy equal weight.
    """
    ref = D if reference is None else reference
    scale = np.linalg.norm(ref, axis=0)
    return D / np.where(scale > 0, scale, 1.0)


def descriptor_distance(DA: np.ndarray, DB: np.ndarray, metric: str = "relative_l1") -> np.ndarray:
    """Pairwise distances between descriptor rows.

    Args:
        DA: (a,d); DB: (b,d) descriptors of the same kind and scaling.
        metric: "l2" (Euclidean), "l1", or "relative_l1" (sum_j |x_j - y_j| / (x_j + y_j), for positive
            descriptors such as HKS/WKS; insensitive to the very different magnitudes across times; the
            default: on SCAPE it beat "l2" by 3-6 points of landmark accuracy for WKS and HKS+WKS, none for HKS).
    Returns:
        (a,b) float, non-negative.
    """
    DA = np.asarray(DA, dtype=np.float64)
    DB = np.asarray(DB, dtype=np.float64)
    if DA.ndim != 2 or DB.ndim != 2 or DA.shape[1] != DB.shape[1]:
        raise ValueError(f"descriptor shapes do not match: {DA.shape} vs {DB.shape}")
    if metric == "l2":
        sq = (DA**2).sum(1)[:, None] + (DB**2).sum(1)[None, :] - 2 * DA @ DB.T
        return np.sqrt(np.maximum(sq, 0.0))
    diff = DA[:, None, :] - DB[None, :, :]  # (a,b,d): fine for landmark sets, O(a b d) memory
    if metric == "l1":
        return np.abs(diff).sum(axis=2)
    if metric == "relative_l1":
        denom = np.abs(DA[:, None, :]) + np.abs(DB[None, :, :])
        return (np.abs(diff) / np.where(denom > 0, denom, 1.0)).sum(axis=2)
    raise ValueError(f"unknown metric {metric!r}")
