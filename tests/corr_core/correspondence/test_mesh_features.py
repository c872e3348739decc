"""Per-mesh inputs of the matchers: spectral, geodesic and flattening features on a unit sphere."""
import numpy as np
import pytest

from corr_core.correspondence import descriptors
from corr_core.correspondence.mesh_features import flattening_features, geodesic_features, spectral_features
from corr_core.geometry import laplacian
from corr_core.geometry.geodesic import landmark_geodesics
from corr_core.geometry.primitives import mesh_edges
from tests.helpers import sphere

LANDMARKS = np.array([3, 150, 420, 777, 901])


@pytest.fixture(scope="module")
def unit_sphere():
    return sphere(1000)


def test_spectral_features_are_hks_and_wks_at_the_landmarks(unit_sphere):
    V, F = unit_sphere
    s = spectral_features(V, F, LANDMARKS, k=20, n_times=8, n_energies=12)
    evals, evecs = laplacian.eigenpairs(V, F, k=20)
    np.testing.assert_allclose(s["hks"], descriptors.hks(evals, evecs[LANDMARKS], n_times=8), rtol=1e-8)
    np.testing.assert_allclose(s["wks"], descriptors.wks(evals, evecs[LANDMARKS], n_energies=12), rtol=1e-8)
    assert s["hks"].shape == (5, 8) and s["wks"].shape == (5, 12) and s["evals"].shape == (20,)


def test_geodesic_features_normalized_by_the_diameter(unit_sphere):
    V, F = unit_sphere
    g = geodesic_features(V, F, LANDMARKS)
    assert g["diameter"] == pytest.approx(np.pi, rel=0.03)
    np.testing.assert_allclose(g["D"], g["D"].T)
    assert g["D"].max() <= 1.0 + 1e-9
    np.testing.assert_allclose(g["D"], landmark_geodesics(V, F, LANDMARKS), rtol=1e-12)
    assert g["chirality"].shape == (5, 5, 5)


def test_flattening_features_layout_and_given_inputs(unit_sphere):
    V, F = unit_sphere
    edges, _ = mesh_edges(F)
    f = flattening_features(V, F, LANDMARKS, n_samples=40)
    assert f["Z"].shape == (len(edges), 2) and f["lam"].shape == (len(edges),) and np.all(f["lam"] > 0)
    np.testing.assert_array_equal(f["edges"], edges)
    assert len(np.unique(f["sample_eids"])) == 40
    for v, e in zip(LANDMARKS, f["landmark_eids"]):
        assert v in f["edges"][e]
    given = flattening_features(V, F, LANDMARKS, Z=2.0 * (f["Z"][:, 0] + 1j * f["Z"][:, 1]), sample_vids=LANDMARKS)
    np.testing.assert_allclose(given["Z"], 2.0 * f["Z"])
    np.testing.assert_allclose(given["lam"], 2.0 * f["lam"], rtol=1e-9)  # scaling the plane scales lam
    np.testing.assert_array_equal(given["sample_eids"], f["landmark_eids"])
