"""Heat-method geodesics on a sampled unit sphere vs the analytic great-circle distance."""
import numpy as np
import pytest

from corr_core.geometry.geodesic import GeodesicSolver, geodesic_diameter, geodesic_distances, landmark_geodesics
from tests.helpers import sphere


@pytest.fixture(scope="module")
def unit_sphere():
    return sphere(2500)


def test_geodesics_match_great_circle(unit_sphere):
    V, F = unit_sphere
    sources = np.array([0, 700, 1900])
    D = geodesic_distances(V, F, sources)
    exact = np.arccos(np.clip(V[sources] @ V.T, -1, 1))
    assert D.shape == (3, len(V))
    err = np.abs(D - exact)
    assert np.median(err) < 0.02  # radians, on a sphere of diameter pi
    assert err.max() < 0.1
    np.testing.assert_allclose(D[np.arange(3), sources], 0, atol=1e-6)


def test_diameter_is_half_circumference(unit_sphere):
    V, F = unit_sphere
    assert geodesic_diameter(V, F) == pytest.approx(np.pi, rel=0.03)


def test_landmark_geodesics_symmetric_and_normalized(unit_sphere):
    V, F = unit_sphere
    vids = np.array([3, 400, 1200, 2222])
    D = landmark_geodesics(V, F, vids)
    np.testing.assert_allclose(D, D.T)
    np.testing.assert_allclose(np.diag(D), 0)
    exact = np.arccos(np.clip(V[vids] @ V[vids].T, -1, 1)) / np.pi
    np.testing.assert_allclose(D, exact, atol=0.03)
    raw = landmark_geodesics(V, F, vids, normalize=False)
    np.testing.assert_allclose(raw / geodesic_diameter(V, F), D, atol=1e-9)


def test_out_of_range_source_raises(unit_sphere):
    V, F = unit_sphere
    with pytest.raises(ValueError):
        geodesic_distances(V, F, [len(V)])


def test_solver_object_reuses_one_factorization(unit_sphere):
    V, F = unit_sphere
    solver = GeodesicSolver(V, F)
    assert solver.n_vertices == len(V)
    D = solver.distances([5, 900])
    np.testing.assert_array_equal(D[1], solver.distance(900))
    np.testing.assert_array_equal(D, geodesic_distances(V, F, [5, 900]))  # same numbers as a fresh solver
    assert solver.diameter() == geodesic_diameter(V, F)
    assert solver.diameter(rounds=1, start=0) == pytest.approx(solver.distance(0).max())
    with pytest.raises(ValueError, match="source ids must be in 0.."):
        solver.distances([-1])
