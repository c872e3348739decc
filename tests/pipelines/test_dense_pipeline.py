"""Dense correspondence through pipelines/scape.yaml on small generated humanoids: both dense methods beside the
course's, a target with other connectivity (decimated pose, true map known by construction), the user's case
"two meshes and only the template's landmarks", and a refinement change that reruns only what depends on it.

All tests share one cache and one first run (module fixtures), coarse spectral settings and coarse meshes
(``grid_step`` 0.03: about 2,600 vertices instead of 4,691), so the module stays cheap.
"""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from corr_core.correspondence.dense import measures as dense_measures
from corr_core.correspondence.landmarks import read_landmarks
from corr_core.generate.humanoid import LANDMARK_NAMES, write_humanoid_dataset
from corr_core.geometry.mesh_io import load_mesh
from shapecorr.dense import _true_map
from shapecorr.generators import _check_humanoid
from stages import api

from tests.helpers import ROOT

SCAPE = ROOT / "pipelines" / "scape.yaml"
GRID_STEP = 0.03       # metres: coarser generated meshes than the default 0.0225
N_POINTS = 300         # dense errors at this many farthest-point template vertices per test mesh
# the default pipeline's settings (pipeline.yaml; at k = 40 dense_auto picks the mirror map on the decimated pose),
# fewer evaluation points and no frequency figures (the course methods' figures: tests/pipelines/test_correspondence_*)
COARSE = ["dense_basis.k=60", "dense_basis.n_samples=1000", "dense_sparse_init.k_init=30",
          "dense_sparse_init.k_end=60", "dense_auto_init.k_init=30", "dense_auto_init.k_end=60",
          "dense_sparse.n_patches=150", "dense_auto.n_patches=150", f"dense_measures.n_points={N_POINTS}",
          "spectral.k=40", "flatten.n_samples=150", "mobius.dense_points=20", "evaluate.frequency_figures=false"]
# floors on these meshes (measured: mean error ~0.01, every point within 0.25, every landmark right)
MEAN_ERROR_CEILING = 0.04
LANDMARK_ACCURACY_FLOOR = 0.9
REFINE_DEPENDENTS = {"dense_auto", "dense_measures", "placed_landmarks", "evaluate", "dense_pictures"}


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """mesh000 (template), mesh001 (a pose, same faces), mesh002 (pose 1 decimated, shuffled ids, with
    ground_truth/mesh002.txt and landmarks/mesh002.txt); one cache for the module."""
    tmp = tmp_path_factory.mktemp("dense")
    info = write_humanoid_dataset(tmp / "humans", n_poses=1, seed=0, remeshed=["decimated"], grid_step=GRID_STEP)
    return {"root": tmp / "humans", "cache": tmp / "cache", "info": info, "tmp": tmp}


def _run(data, root, out, client, sets=()):
    return api.run(str(SCAPE), [f"data.root={root}", *COARSE, *sets], client_getter=lambda: client, quiet=True,
                   cache_dir=str(data["cache"]), output_dir=str(out))


def _metrics(data, root, out, sets=()):
    return api.metrics(api.plan_pipeline(str(SCAPE), [f"data.root={root}", *COARSE, *sets],
                                         cache_dir=str(data["cache"]), output_dir=str(out), quiet=True))


@pytest.fixture(scope="module")
def first_run(data, dask_client):
    """The cold run of the whole pipeline on ``data``, shared by the tests that read it:
    {"summary": run summary, "metrics": results, "out": output folder}."""
    out = data["tmp"] / "out"
    summary = _run(data, data["root"], out, dask_client)
    return {"summary": summary, "metrics": _metrics(data, data["root"], out), "out": out}


def test_both_dense_methods_beside_the_course_methods(first_run):
    s, m = first_run["summary"], first_run["metrics"]
    assert not s["failures"]
    assert s["stages"]["dense_basis"]["tasks"] == 3            # once per mesh, shared by both methods
    for method in ("dense_sparse", "dense_auto"):
        assert set(m["dense"][method]) == {"mean_error", "within_0.05", "within_0.10", "within_0.25"}
        assert 0.0 <= m["dense"][method]["mean_error"] <= 1.0 and 0.0 <= m["accuracy"][method] <= 1.0
        assert set(m["accuracy_per_mesh"][method]) == {"mesh001", "mesh002"}   # the decimated one is scored
    # accuracy floors for dense_sparse only: dense_auto (map_automatic) still picks the mirror map on some poses
    # and is being reworked in corr_core (issue 10); its numbers are reported, not asserted, until then
    assert m["dense"]["dense_sparse"]["mean_error"] <= MEAN_ERROR_CEILING, m["dense"]
    assert m["dense"]["dense_sparse"]["within_0.25"] == 1.0, m["dense"]
    assert m["accuracy"]["dense_sparse"] >= LANDMARK_ACCURACY_FLOOR, m["accuracy"]
    assert {"descriptor", "mrf_oriented", "mobius_all"} <= set(m["accuracy"])
    # n_points farthest-point template vertices on each test mesh, Möbius measured at the same vertices
    assert m["dense_n_points"] == {k: 2 * N_POINTS for k in ("mobius", "dense_sparse", "dense_auto")}


def test_kim_curves_and_pulled_back_pictures_are_published(first_run):
    out = first_run["out"]
    assert (out / "evaluate" / "kim_curves.png").read_bytes()[:4] == b"\x89PNG"
    assert not list((out / "evaluate").glob("frequency_*.png"))   # evaluate.frequency_figures=false
    for method in ("mobius", "dense_sparse", "dense_auto"):
        assert (out / "dense_pictures" / f"dense_{method}.png").is_file()


def test_placed_landmarks_have_the_template_names_and_land_near_the_truth(data, first_run):
    """One file per method and test mesh, the template's names, close to the truth on the decimated pose."""
    out, m = first_run["out"], first_run["metrics"]
    truth = np.loadtxt(data["root"] / "ground_truth" / "mesh002.txt", dtype=np.int64)
    ids, names = read_landmarks(data["root"] / "landmark_vids.txt")
    placed, placed_names = read_landmarks(out / "placed_landmarks" / "dense_sparse" / "mesh002.txt")
    assert placed_names == names == LANDMARK_NAMES
    V, F = load_mesh(data["root"] / "meshes" / "test" / "mesh002.obj")
    errors, nearest = dense_measures.landmark_errors(V, F, placed, truth[ids])
    assert dense_measures.landmark_accuracy(nearest) >= LANDMARK_ACCURACY_FLOOR
    assert m["accuracy_per_mesh"]["dense_sparse"]["mesh002"] == dense_measures.landmark_accuracy(nearest)
    for method in ("dense_sparse", "dense_auto"):
        for mesh in ("mesh001", "mesh002"):
            assert (out / "placed_landmarks" / method / f"{mesh}.txt").is_file()


def test_two_meshes_and_only_the_template_landmarks(data, tmp_path, dask_client):
    """The user's case: template + one scan of other connectivity, landmarks only for the template."""
    root = tmp_path / "mine"
    (root / "meshes" / "template").mkdir(parents=True)
    (root / "meshes" / "test").mkdir()
    shutil.copy(data["root"] / "meshes" / "template" / "mesh000.obj", root / "meshes" / "template")
    shutil.copy(data["root"] / "meshes" / "test" / "mesh002.obj", root / "meshes" / "test")  # same name: cached
    for f in ("landmark_vids.txt", "sparse_landmark_vids.txt"):
        shutil.copy(data["root"] / f, root / f)
    s = _run(data, root, tmp_path / "out", dask_client)
    assert not s["failures"]
    m = _metrics(data, root, tmp_path / "out")
    assert "no landmarks" in m["not_scored"]["mesh002"]                     # course methods skipped, saying why
    assert "no landmarks" in m["dense_skipped"]["dense_sparse"]["mesh002"]  # needs the 5 points on the target
    assert "ground_truth/mesh002.txt" in m["dense_not_measured"]["mesh002"]
    assert "dense" not in m and m["accuracy"] == {}
    placed, names = read_landmarks(tmp_path / "out" / "placed_landmarks" / "dense_auto" / "mesh002.txt")
    assert names == LANDMARK_NAMES
    truth = np.loadtxt(data["root"] / "ground_truth" / "mesh002.txt", dtype=np.int64)   # known to us only
    ids, _ = read_landmarks(root / "landmark_vids.txt")
    V, F = load_mesh(root / "meshes" / "test" / "mesh002.obj")
    assert placed.min() >= 0 and placed.max() < len(V) and len(np.unique(placed)) > len(placed) // 2
    errors, _ = dense_measures.landmark_errors(V, F, placed, truth[ids])   # measurable with the hidden truth
    assert np.all(np.isfinite(errors))


def test_refinement_params_rerun_only_the_refinement_and_the_evaluation(data, first_run, dask_client):
    s = _run(data, data["root"], first_run["out"], dask_client, ["dense_auto.rounds=2"])
    executed = {name for name, st in s["stages"].items() if st["executed"]}
    assert executed == REFINE_DEPENDENTS
    assert s["stages"]["dense_auto"]["executed"] == 2 and s["stages"]["dense_basis"]["cached"] == 3


def test_bad_ground_truth_file_fails_naming_it(tmp_path):
    template = {"V": np.zeros((5, 3)), "F": np.array([[0, 1, 2]])}
    target = {"V": np.zeros((4, 3)), "F": np.array([[0, 1, 2]])}
    (tmp_path / "scan.txt").write_text("1\n2\n3\n")
    with pytest.raises(ValueError, match="scan.txt: must hold 5 target vertex ids .* got 3 ids"):
        _true_map(template, target, str(tmp_path), "scan")
    (tmp_path / "scan.txt").write_text("0\n1\n2\n3\n4\n")
    with pytest.raises(ValueError, match="in 0..3; got 5 ids in 0..4"):
        _true_map(template, target, str(tmp_path), "scan")
    truth, source = _true_map(template, target, str(tmp_path), "other")
    assert truth is None and "no ground_truth/other.txt" in source


def test_generator_params_are_checked():
    _check_humanoid(n_poses=2, seed=0, vary_bodies=True, remeshed=["decimated", "subdivided"])
    with pytest.raises(ValueError, match="'remeshed'.*unknown kinds \\['wobbly'\\]"):
        _check_humanoid(n_poses=2, seed=0, remeshed=["wobbly"])
    with pytest.raises(ValueError, match="at most n_poses = 1"):
        _check_humanoid(n_poses=1, seed=0, remeshed=["decimated", "decimated"])


def test_dense_auto_init_on_a_two_triangle_mesh_names_the_file(tmp_path):
    """A target of two triangles has too few extremities for the automatic initialisation: the error names the
    target's file and item (it said only "need at least 3 feature points on each mesh, got 5 and 2")."""
    from corr_core.geometry.mesh_io import save_obj
    from shapecorr.correspondence import mesh
    from shapecorr.dense import dense_basis, dense_init

    from tests.helpers import sphere

    V, F = sphere(600)
    n = V / np.linalg.norm(V, axis=1, keepdims=True)
    tips = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]) / np.sqrt(3)
    save_obj(tmp_path / "star.obj", n * (1 + 1.5 * (np.clip(n @ tips.T, 0, None) ** 6).sum(1))[:, None], F)  # 4 tips
    save_obj(tmp_path / "flat.obj", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]]),
             np.array([[0, 1, 2], [1, 3, 2]]))
    template, target = mesh(str(tmp_path / "star.obj"), item_name="star"), mesh(str(tmp_path / "flat.obj"),
                                                                              item_name="scan_7")
    bases = [dense_basis(m, k=30, n_samples=200) for m in (template, target)]
    with pytest.raises(ValueError) as err:
        dense_init(*bases, template, target, None, None, mode="auto", k_init=10, k_end=30)
    msg = str(err.value)
    assert msg.startswith("flat.obj (item scan_7)") and "the target has 2" in msg and "template" in msg
    assert "sparse" in msg                                   # what to do
