"""Cotangent Laplace–Beltrami operator and its low-frequency eigenpairs.

Sign convention: ``L`` here is the *positive* semi-definite stiffness matrix (diagonal > 0, off-diagonal <= 0),
as returned by ``robust_laplacian.mesh_laplacian``. libigl's ``cotmatrix`` is its negative.
The generalized eigenproblem is ``L phi = lambda M phi`` with ``0 = lambda_0 <= lambda_1 <= ...``.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla


def laplacian_and_mass(V: np.ndarray, F: np.ndarray, mollify_factor: float = 1e-5) -> tuple[sp.csr_matrix, sp.dia_matrix]:
    """Cotan stiffness and lumped (Voronoi-like) mass matrices of a triangle mesh.

    Args:
        V: (n,3) float vertex positions.
        F: (m,3) int triangles.
        mollify_factor: intrinsic mollification passed to robust_laplacian (guards near-degenerate triangles).
    Returns:
        L: (n,n) sparse, symmetric positive semi-definite (L @ 1 == 0); units: dimensionless (cotangent weights).
        M: (n,n) sparse diagonal, positive; units: area (the area of the surface around each vertex).
    """
    import robust_laplacian

    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    L, M = robust_laplacian.mesh_laplacian(V, F, mollify_factor=mollify_factor)
    return sp.csr_matrix(L), sp.dia_matrix(M)


def eigenpairs(V: np.ndarray, F: np.ndarray, k: int = 100, sigma: float = -1e-6) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest Laplace–Beltrami eigenpairs of ``L phi = lambda M phi``.

    Uses scipy ``eigsh`` in shift-invert mode around a slightly negative ``sigma`` (``L - sigma M`` is then
    positive definite, so the factorization is well posed even though ``L`` is singular).

    Args:
        V: (n,3) float vertex positions; F: (m,3) int triangles.
        k: number of eigenpairs (k < n).
        sigma: shift; keep it small and negative relative to lambda_1 (units 1/area).
    Returns:
        evals: (k,) float ascending, evals[0] ~ 0 (units 1/area).
        evecs: (n,k) float, M-orthonormal: evecs.T @ M @ evecs == I.
    """
    L, M = laplacian_and_mass(V, F)
    n = L.shape[0]
    if not 0 < k < n:
        raise ValueError(f"k must be in 1..{n - 1}, got {k}")
    evals, evecs = sla.eigsh(L.tocsc(), k=k, M=M.tocsc(), sigma=sigma, which="LM")
    order = np.argsort(evals)
    evals, evecs = evals[order], evecs[:, order]
    evals = np.maximum(evals, 0.0)
    # eigsh returns M-orthonormal vectors already; renormalize for safety with near-repeated eigenvalues.
    norms = np.sqrt(np.einsum("ik,ik->k", evecs, M @ evecs))
    return evals, evecs / norms
