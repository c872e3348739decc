"""Cotangent Laplace–Beltrami operators and the low-frequency eigenpairs.

``laplacian_and_mass`` / ``eigenpairs``: robust_laplacian's intrinsic-mollified cotan stiffness and lumped mass
(spectral descriptors). ``cotan_laplacian``: the plain cotan stiffness of the given triangles (mid-edge
flattening, where the harmonic function must be discrete harmonic for exactly these triangles).

Sign convention: ``L`` here is the *positive* semi-definite stiffness matrix (diagonal > 0, off-diagonal <= 0),
as returned by ``robust_laplacian.mesh_laplacian``. libigl's ``cotmatrix`` is its negative.
The generalized eigenproblem is ``L phi = lambda M phi`` with ``0 = lambda_0 <= lambda_1 <= ...``.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla


def laplacian_and_mass(V: np.ndarray, F: np.ndarray, *,
                       mollify_factor: float = 1e-5) -> tuple[sp.csr_matrix, sp.dia_matrix]:
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


def start_vector(n: int, *, seed: int = 0) -> np.ndarray:
    """(n,) float64 fixed Lanczos start vector for ``eigsh``: the same inputs give bit-identical eigenpairs.

    Without ``v0`` ARPACK starts from a random vector, so eigenvectors differ by ~1e-15 from run to run, enough
    to flip ties downstream (e.g. the descriptor matching of a symmetric shape). A seeded random vector, not a
    smooth one: a start vector close to an eigenvector (e.g. the constant one) can make Lanczos miss eigenpairs.
    """
    return np.random.default_rng(seed).uniform(-1.0, 1.0, n)


def eigenpairs(V: np.ndarray, F: np.ndarray, *, k: int = 100, sigma: float = -1e-6) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest Laplace–Beltrami eigenpairs of ``L phi = lambda M phi``.

    Uses scipy ``eigsh`` in shift-invert mode around a slightly negative ``sigma`` (``L - sigma M`` is then
    positive definite, so the factorization is well posed even though ``L`` is singular), started from the fixed
    ``start_vector(n)`` so that the result is the same on every run.

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
    evals, evecs = sla.eigsh(L.tocsc(), k=k, M=M.tocsc(), sigma=sigma, which="LM", v0=start_vector(n))
    order = np.argsort(evals, kind="stable")
    evals, evecs = evals[order], evecs[:, order]
    evals = np.maximum(evals, 0.0)
    # eigsh returns M-orthonormal vectors already; renormalize for safety with near-repeated eigenvalues.
    norms = np.sqrt(np.einsum("ik,ik->k", evecs, M @ evecs))
    return evals, evecs / norms


def cotan_laplacian(V: np.ndarray, F: np.ndarray) -> sp.csr_matrix:
    """Positive semi-definite cotan Laplacian ``L`` (n,n): ``(L u)_i = sum_j w_ij (u_i - u_j)``,
    ``w_ij = (cot alpha + cot beta) / 2``. V: (n,3) float, F: (m,3) int."""
    V = np.asarray(V, dtype=float)
    n = len(V)
    rows, cols, vals = [], [], []
    for k in range(3):                      # angle at corner k weights the opposite edge (i, j)
        i, j, o = F[:, (k + 1) % 3], F[:, (k + 2) % 3], F[:, k]
        a, b = V[i] - V[o], V[j] - V[o]
        cot = np.einsum("ij,ij->i", a, b) / np.maximum(np.linalg.norm(np.cross(a, b), axis=1), 1e-300)
        w = 0.5 * cot
        rows += [i, j, i, j]
        cols += [j, i, i, j]
        vals += [-w, -w, w, w]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
