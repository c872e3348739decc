"""IntrinsicMesh: intrinsic methods run on the largest component of the referenced vertices, in original ids."""
from __future__ import annotations

import numpy as np
import pytest

from corr_core.correspondence import mesh_features
from corr_core.geometry.geodesic import GeodesicSolver
from corr_core.geometry.intrinsic import IntrinsicMesh, OutsideComponentError
from corr_core.generate.defects import with_fins
from tests.helpers import sphere

LANDMARKS = np.array([0, 40, 120, 250, 399])


def _dirty(V, F):
    """5 unused vertices spread among the ids and a small loose triangle pair appended; new_id: (n,) int."""
    n = len(V)
    new_id = np.arange(n) + np.searchsorted([0, 100, 200, 300, 399], np.arange(n), side="right")
    V2 = np.full((n + 5, 3), 1e3)
    V2[new_id] = V
    piece = np.array([[3.0, 0, 0], [3.1, 0, 0], [3.0, 0.1, 0], [3.1, 0.1, 0.05]])
    F_piece = np.array([[0, 1, 2], [1, 3, 2]]) + len(V2)
    return np.concatenate([V2, piece]), np.concatenate([new_id[F], F_piece]), new_id


@pytest.fixture(scope="module")
def meshes():
    V, F = sphere(400)
    return (V, F), _dirty(V, F)


def test_clean_mesh_is_the_identity(meshes):
    (V, F), _ = meshes
    surface = IntrinsicMesh(V, F)
    assert surface.is_identity
    np.testing.assert_array_equal(surface.V, V)
    np.testing.assert_array_equal(surface.F, F)
    values = np.arange(len(V))
    assert surface.to_full(values) is values
    np.testing.assert_array_equal(surface.to_sub(LANDMARKS), LANDMARKS)


def test_keeps_the_largest_component_and_maps_ids_both_ways(meshes):
    (V, F), (V2, F2, new_id) = meshes
    surface = IntrinsicMesh(V2, F2)
    assert not surface.is_identity and surface.n_full == len(V2)
    np.testing.assert_array_equal(surface.vids, new_id)
    np.testing.assert_array_equal(surface.V, V)
    np.testing.assert_array_equal(surface.F, F)
    np.testing.assert_array_equal(surface.to_sub(new_id[LANDMARKS]), LANDMARKS)
    full = surface.to_full(np.arange(len(V), dtype=float))
    assert full.shape == (len(V2),) and np.isnan(np.delete(full, new_id)).all()
    np.testing.assert_array_equal(full[new_id], np.arange(len(V)))
    ids = surface.to_full(np.arange(len(V)), fill=-1)
    assert ids.dtype.kind == "i" and (np.delete(ids, new_id) == -1).all()


def test_a_vertex_off_the_component_is_a_clear_error(meshes):
    _, (V2, F2, _) = meshes
    surface = IntrinsicMesh(V2, F2)
    loose = len(V2) - 1
    with pytest.raises(OutsideComponentError, match=rf"landmark 'Nose' \(vertex {loose}\) from lm.txt is not on"):
        surface.to_sub([loose], what="landmark", names=["Nose"], source="lm.txt")
    with pytest.raises(OutsideComponentError, match="landmark 0"):  # an unused vertex
        surface.to_sub([0, 1], what="landmark")


def test_geodesics_are_the_clean_ones_in_original_ids(meshes):
    (V, F), (V2, F2, new_id) = meshes
    clean, dirty = GeodesicSolver(V, F), GeodesicSolver(V2, F2)
    D = dirty.distances(new_id[LANDMARKS])
    np.testing.assert_array_equal(D[:, new_id], clean.distances(LANDMARKS))
    assert np.isnan(np.delete(D, new_id, axis=1)).all()
    assert dirty.diameter() == clean.diameter()


def test_fins_are_left_out_and_geodesics_are_the_clean_ones(meshes):
    """Triangles standing on edges (non-manifold) are not surface: their apexes are off the kept mesh, and the
    geodesics are those of the mesh without them."""
    (V, F), _ = meshes
    V2, F2 = with_fins(V, F, 6)
    surface = IntrinsicMesh(V2, F2)
    assert not surface.is_identity and len(surface.vids) == len(V)
    np.testing.assert_array_equal(surface.F, F)
    assert not surface.contains(np.arange(len(V), len(V2))).any()
    np.testing.assert_array_equal(GeodesicSolver(V2, F2).distances(LANDMARKS)[:, :len(V)],
                                  GeodesicSolver(V, F).distances(LANDMARKS))


def test_features_are_the_clean_ones(meshes):
    (V, F), (V2, F2, new_id) = meshes
    s0 = mesh_features.spectral_features(V, F, LANDMARKS, k=20)
    s1 = mesh_features.spectral_features(V2, F2, new_id[LANDMARKS], k=20)
    for key in s0:
        np.testing.assert_array_equal(s0[key], s1[key])
    g0 = mesh_features.geodesic_features(V, F, LANDMARKS)
    g1 = mesh_features.geodesic_features(V2, F2, new_id[LANDMARKS])
    for key in g0:
        np.testing.assert_array_equal(g0[key], g1[key])
    f0 = mesh_features.flattening_features(V, F, LANDMARKS, n_samples=50)
    f1 = mesh_features.flattening_features(V2, F2, new_id[LANDMARKS], n_samples=50)
    for key in ("Z", "lam", "landmark_eids", "sample_eids"):
        np.testing.assert_array_equal(f0[key], f1[key])
    np.testing.assert_array_equal(new_id[f0["edges"]], f1["edges"])
    assert np.isfinite(f1["Z"]).all()
    given = mesh_features.flattening_features(V2, F2, new_id[LANDMARKS], sample_vids=[0, new_id[5], len(V2) - 1])
    assert len(given["sample_eids"]) == 1  # samples off the component are left out
