"""Generated tables: their declared symmetry order holds for the geometry, and the collection's ground truth;
continuous chair azimuths leave the default collection unchanged."""

import csv

import numpy as np
import pytest
from scipy.spatial import cKDTree

from corr_core.generate.chairs import collection_azimuths, write_chair_collection
from corr_core.generate.tables import SYMMETRY_ORDER, TABLE_KINDS, make_table, write_table_collection
from corr_core.geometry.primitives import rotate_about_y


def looks_the_same(V, angle):
    """True when V turned by ``angle`` about +y lands on its own vertex set (to 1e-9)."""
    return cKDTree(V).query(rotate_about_y(V, angle))[0].max() < 1e-9


@pytest.mark.parametrize("kind", TABLE_KINDS)
def test_table_symmetry_order_holds(kind):
    V, _ = make_table(np.random.default_rng([0, 1, 7]), kind)
    k = SYMMETRY_ORDER[kind]
    if k == 0:
        assert looks_the_same(V, 2 * np.pi / 48)  # the discs' segments
    else:
        assert looks_the_same(V, 2 * np.pi / k) and not looks_the_same(V, np.pi / k)


def test_table_collection_ground_truth(tmp_path):
    out = write_table_collection(tmp_path, n=4, n_chairs=2, seed=3)
    rows = list(csv.DictReader(open(tmp_path / "ground_truth.csv")))
    assert [r["kind"] for r in rows] == ["round", "square", "rectangular", "round", "chair", "chair"]
    assert [int(r["symmetry_order"]) for r in rows] == [0, 4, 2, 0, 1, 1] == out["symmetry_order"]
    deg = np.array([float(r["azimuth_deg"]) for r in rows])
    np.testing.assert_allclose(deg, collection_azimuths(6, 3, 16, True)[1], atol=1e-6)
    assert [int(r["azimuth_steps"]) for r in rows] == list(np.rint(deg / 22.5).astype(int) % 16)


def test_continuous_chairs_keep_the_shapes_and_default_azimuths(tmp_path):
    steps = write_chair_collection(tmp_path / "a", n=5, seed=2)["azimuth_steps"]
    assert steps == list(np.random.default_rng([2, 0]).integers(0, 16, size=5))  # the default is unchanged
    cont = write_chair_collection(tmp_path / "b", n=5, seed=2, continuous=True)
    assert not np.allclose(np.array(cont["azimuth_deg"]) % 22.5, 0)
