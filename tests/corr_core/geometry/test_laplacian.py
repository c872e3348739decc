"""Cotan Laplacian and eigenpairs on a sampled unit sphere: eigenvalues l(l+1) with multiplicity 2l+1."""
import numpy as np
import pytest

from tests.helpers import sphere
from corr_core.geometry.laplacian import eigenpairs, laplacian_and_mass


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
