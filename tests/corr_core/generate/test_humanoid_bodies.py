"""Different bodies (not only poses) and other triangulations from the humanoid generator."""
from __future__ import annotations

import numpy as np
import pytest

from corr_core.generate import humanoid as H
from corr_core.geometry.mesh_io import load_mesh


@pytest.fixture(scope="module")
def rest():
    V, F = H.make_humanoid_rest()
    W, _ = H.skinning_weights(V, F)
    return V, F, W


def test_neutral_body_is_the_rest_mesh(rest):
    V, F, W = rest
    Vb, Jb = H.shape_body(V, W, H.neutral_body())
    np.testing.assert_allclose(Vb, V, atol=1e-12)
    for name, p in H.skeleton().items():
        np.testing.assert_allclose(Jb[name], p, atol=1e-12)


def test_bodies_change_proportions_not_connectivity(rest):
    V, F, W = rest
    long_arms, _ = H.shape_body(V, W, {"arm_length": 1.15})
    lms = H.landmark_vertices(V)
    hand, shoulder = lms["Left Hand"], lms["Left Sholder"]
    reach = lambda X: np.linalg.norm(X[hand] - X[shoulder])  # noqa: E731
    assert reach(long_arms) > 1.08 * reach(V)
    fat, _ = H.shape_body(V, W, {"leg_girth": 1.3})
    knee = lms["Left Knee"]
    shin = np.abs(V[:, 1] - V[knee, 1]) < 0.03            # a ring around the left knee, by height
    shin &= V[:, 0] > 0.03
    radius = lambda X: np.linalg.norm(X[shin][:, [0, 2]] - X[shin][:, [0, 2]].mean(0), axis=1).mean()  # noqa: E731
    assert radius(fat) > 1.2 * radius(V)
    assert abs(fat[:, 1].min() - V[:, 1].min()) < 1e-9     # still standing on the floor
    with pytest.raises(ValueError, match="unknown body factors.*'arm_lenght'"):
        H.shape_body(V, W, {"arm_lenght": 1.1})


def test_varied_bodies_deterministic_same_faces_same_poses(tmp_path):
    a = H.write_humanoid_dataset(tmp_path / "a", n_poses=2, seed=3, vary_bodies=True)
    b = H.write_humanoid_dataset(tmp_path / "b", n_poses=2, seed=3, vary_bodies=True)
    same = H.write_humanoid_dataset(tmp_path / "c", n_poses=2, seed=3)
    assert a["poses"] == same["poses"] and a["bodies"] == b["bodies"]
    assert a["bodies"][0] != a["bodies"][1] and set(a["bodies"][0]) == set(H.BODY_RANGES)
    V0, F0 = load_mesh(a["template"])
    for pa, pb, ps in zip(a["tests"], b["tests"], same["tests"]):
        (Va, Fa), (Vb, _), (Vs, _) = load_mesh(pa), load_mesh(pb), load_mesh(ps)
        np.testing.assert_array_equal(Fa, F0)
        np.testing.assert_array_equal(Va, Vb)
        assert np.abs(Va - Vs).max() > 0.02                 # another person, not only another pose


@pytest.mark.parametrize("kind", H.REMESH_KINDS)
def test_remesh_truth_by_construction(rest, kind):
    V, F, _ = rest
    V2, F2, truth = H.remesh(V, F, kind, seed=1)
    assert len(V2) != len(V) and truth.shape == (len(V),)
    assert len(np.unique(F2.ravel())) == len(V2)            # no unused vertex
    edge = np.median(np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1))
    err = np.linalg.norm(V2[truth] - V, axis=1)
    if kind == "subdivided":
        assert err.max() < 1e-12
    else:
        assert np.median(err) < edge
    assert np.mean(truth == np.arange(len(V))) < 0.01       # vertex ids shuffled


def test_remeshed_targets_written_with_truth_and_landmarks(tmp_path):
    info = H.write_humanoid_dataset(tmp_path, n_poses=1, seed=0, remeshed=["decimated"])
    name = "mesh002"
    V2, _ = load_mesh(tmp_path / "meshes" / "test" / f"{name}.obj")
    truth = np.loadtxt(tmp_path / "ground_truth" / f"{name}.txt", dtype=np.int64)
    assert truth.shape == (info["n_vertices"],) and truth.max() < len(V2) == info["remeshed"][name]["n_vertices"]
    lines = (tmp_path / "landmarks" / f"{name}.txt").read_text().splitlines()
    assert [ln.split(",")[1] for ln in lines] == H.LANDMARK_NAMES
    assert [int(ln.split(",")[0]) for ln in lines] == [int(truth[info["landmarks"][n]]) for n in H.LANDMARK_NAMES]
    with pytest.raises(ValueError, match="remeshed"):
        H.write_humanoid_dataset(tmp_path / "x", n_poses=1, remeshed=["decimated", "subdivided"])
