"""Cotan Laplacian and eigenpairs on a sampled unit sphere: eigenvalues l(l+1) with multiplicity 2l+1."""
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from corr_core.geometry.laplacian import eigenpairs, laplacian_and_mass


def sphere(n=1500, seed=0):
    """Unit sphere: Fibonacci points + convex hull, faces oriented outward. V: (n,3), F: (m,3)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    V = np.c_[np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)]
    F = ConvexHull(V).simplices
    nrm = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    flip = np.einsum("ij,ij->i", nrm, V[F].mean(1)) < 0
    F[flip] = F[flip][:, ::-1]
    return V, F


def test_laplacian_is_psd_with_constant_kernel_and_mass_is_area():
    V, F = sphere(600)
    L, M = laplacian_and_mass(V, F)
    assert abs(L @ np.ones(len(V))).max() < 1e-10
    assert np.all(L.diagonal() > 0)  # positive convention (libigl's cotmatrix is the negative)
    assert abs(L - L.T).max() < 1e-12
    x = np.random.default_rng(0).normal(size=len(V))
    assert x @ (L @ x) > 0
    assert M.diagonal().sum() == pytest.approx(4 * np.pi, rel=0.01)  # inscribed polyhedron: slightly less


def test_sphere_spectrum_and_m_orthonormality():
    V, F = sphere(1500)
    evals, evecs = eigenpairs(V, F, k=16)
    expected = np.repeat([0, 2, 6, 12], [1, 3, 5, 7]).astype(float)
    assert evals[0] == pytest.approx(0, abs=1e-6)
    np.testing.assert_allclose(evals[1:], expected[1:], rtol=0.02)
    _, M = laplacian_and_mass(V, F)
    np.testing.assert_allclose(evecs.T @ (M @ evecs), np.eye(16), atol=1e-8)
    assert np.all(np.diff(evals) >= -1e-9)


def test_k_out_of_range_raises():
    V, F = sphere(100)
    with pytest.raises(ValueError):
        eigenpairs(V, F, k=100)
