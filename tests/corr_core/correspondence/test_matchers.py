"""Composed matchers: a permuted copy of the template is matched back, on all and on the sparse landmarks."""
import numpy as np
import pytest

from corr_core.correspondence.matchers import (descriptor_matrix, match_descriptors, match_geodesic_mrf,
                                               match_mobius)
from corr_core.correspondence.mesh_features import flattening_features, geodesic_features
from corr_core.geometry.primitives import surface_area
from tests.helpers import sphere

SPARSE = np.array([0, 2, 4, 5, 7])


def blob():
    """A bumpy, asymmetric closed surface (no intrinsic symmetry) with 8 spread-out landmarks."""
    V, F = sphere(900)
    bump = np.exp(-((V[:, 0] - 0.6) ** 2 + (V[:, 2] - 0.5) ** 2) / 0.1)
    r = 1 + 0.35 * bump + 0.25 * np.exp(-(V[:, 1] + 0.7) ** 2 / 0.1)
    V = V * r[:, None] * [1.0, 0.8, 1.4]
    return V, F, np.array([10, 120, 250, 380, 500, 610, 730, 850])


def test_descriptor_matrix_kinds():
    s = {"hks": np.ones((3, 2)), "wks": np.zeros((3, 4))}
    assert descriptor_matrix(s, "hks").shape == (3, 2) and descriptor_matrix(s, "wks").shape == (3, 4)
    np.testing.assert_array_equal(descriptor_matrix(s, "hks+wks"), np.c_[s["hks"], s["wks"]])
    with pytest.raises(ValueError, match="descriptor must be hks, wks or hks\\+wks"):
        descriptor_matrix(s, "sift")


def test_descriptor_matching_recovers_a_permutation():
    rng = np.random.default_rng(0)
    template = {"hks": rng.random((8, 5)) + 0.1, "wks": rng.random((8, 6)) + 0.1}
    perm = rng.permutation(8)  # template landmark i is target landmark perm[i]
    inv = np.argsort(perm)
    target = {k: v[inv] for k, v in template.items()}
    out = match_descriptors(template, target, np.arange(8))
    np.testing.assert_array_equal(out["all"], perm)
    sparse_only = match_descriptors(template, template, SPARSE, descriptor="wks", metric="l2")
    np.testing.assert_array_equal(sparse_only["sparse"], np.arange(len(SPARSE)))  # indexes the sparse subset


@pytest.mark.parametrize("orientation_test", [False, True])
def test_geodesic_mrf_matches_the_same_surface_to_itself(orientation_test):
    V, F, lm = blob()
    g = geodesic_features(V, F, lm)
    out = match_geodesic_mrf(g, g, SPARSE, orientation_test=orientation_test)
    np.testing.assert_array_equal(out["all"], np.arange(len(lm)))
    np.testing.assert_array_equal(out["sparse"], np.arange(len(SPARSE)))


def test_mobius_matching_with_dense_errors_and_skipped_dense_map():
    V, F, lm = blob()
    flat = flattening_features(V, F, lm, n_samples=80)
    mesh = {"V": V, "F": F, "area": surface_area(V, F)}
    out = match_mobius(flat, flat, mesh, mesh, SPARSE, top=10, dense_points=30)
    np.testing.assert_array_equal(out["sparse"], np.arange(len(SPARSE)))
    np.testing.assert_array_equal(out["all"], np.arange(len(lm)))
    assert out["best_score"] > 0.9
    assert out["dense_errors"].shape == (30,) and np.median(out["dense_errors"]) < 0.05
    other = {**mesh, "F": F[::-1][:-1]}  # a face less: no vertex i <-> vertex i truth
    skipped = match_mobius(flat, flat, mesh, other, SPARSE, top=10, dense_points=30)
    assert "dense_errors" not in skipped and "same triangles are required" in skipped["dense_skipped"]
    appended = {**mesh, "V": np.concatenate([V, V[:2] + 3.0])}   # 2 unused vertices appended: same triangles
    kept = match_mobius(flat, flat, mesh, appended, SPARSE, top=10, dense_points=30)
    assert "dense_skipped" not in kept and kept["dense_errors"].shape == (30,)


def test_mobius_vertex_map_of_a_surface_to_itself_and_with_stray_vertices():
    """match_mobius's dense vertex map: near-identity on the same surface, -1 for vertices on no face."""
    V, F, lm = blob()
    flat = flattening_features(V, F, lm, n_samples=80)
    mesh = {"V": V, "F": F, "area": surface_area(V, F)}
    vm = match_mobius(flat, flat, mesh, mesh, SPARSE, dense_points=0)["vertex_map"]
    assert vm.shape == (len(V),) and vm.min() >= 0
    # the identity up to the midpoint -> vertex rounding: each vertex lands on itself or a neighbour
    edge = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).mean()
    assert np.median(np.linalg.norm(V[vm] - V, axis=1)) <= 1.5 * edge
    # two stray vertices used by no face (ids kept): no image for them, the others unchanged
    V2 = np.vstack([V, [[9.0, 9.0, 9.0], [-9.0, 9.0, 9.0]]])
    flat2 = flattening_features(V2, F, lm, n_samples=80)
    mesh2 = {**mesh, "V": V2}
    vm2 = match_mobius(flat2, flat2, mesh2, mesh2, SPARSE, dense_points=0)["vertex_map"]
    np.testing.assert_array_equal(vm2[-2:], [-1, -1])
    np.testing.assert_array_equal(vm2[:-2], vm)
