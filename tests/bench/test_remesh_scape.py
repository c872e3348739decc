"""bench/remesh_scape.py and the ground truth bench/correspondence.py reads from it (course data: the template
and one pose, each decimated on its own)."""
from __future__ import annotations

import numpy as np
import pytest

from tests.helpers import COURSE_DATA

SCAPE = COURSE_DATA / "scape"


@pytest.fixture(scope="module")
def remeshed(tmp_path_factory):
    """The template and the first pose remeshed (seed 0) into a fresh folder: (folder, info of remesh_set)."""
    from bench.remesh_scape import remesh_set

    out = tmp_path_factory.mktemp("remeshed") / "scape"
    return out, remesh_set(str(SCAPE), str(out), seed=0, poses=1)


def _mesh(path):
    from corr_core.geometry.mesh_io import load_mesh

    return load_mesh(str(path))


@pytest.mark.course
def test_every_mesh_has_its_own_triangulation_and_size(remeshed):
    from bench.remesh_scape import MAX_VERTICES, MIN_VERTICES
    from corr_core.correspondence.measures import numbering_problem
    from corr_core.geometry.intrinsic import IntrinsicMesh

    out, info = remeshed
    Vs, Fs = _mesh(out / "meshes/template/mesh000.obj")
    Vt, Ft = _mesh(out / "meshes/test/mesh002.obj")
    for V, F in ((Vs, Fs), (Vt, Ft)):
        assert MIN_VERTICES * 0.9 <= len(V) <= MAX_VERTICES * 1.1
        assert IntrinsicMesh(V, F).is_identity               # one component, every vertex used
    assert numbering_problem(Fs, Ft) is not None
    assert len(Vs) != len(Vt) or not np.array_equal(Fs, Ft)
    assert info["mesh002"]["n_vertices"] == len(Vt)


@pytest.mark.course
def test_the_loaders_read_the_files_and_the_truth_meets_the_own_landmarks(remeshed):
    """The true map of bench/correspondence.py (from ground_truth/) sends the template's landmarks to within the
    snap distances of the pose's own landmarks (from landmarks/, snapped on the pose, another route); vertex
    i <-> vertex i, or the template's landmark ids on the pose, would not."""
    from bench.correspondence import sparse_pairs, target_landmarks, true_map
    from corr_core.correspondence.landmarks import read_landmarks

    out, info = remeshed
    Vs, _ = _mesh(out / "meshes/template/mesh000.obj")
    Vt, Ft = _mesh(out / "meshes/test/mesh002.obj")
    truth, source = true_map(str(out), "mesh002", len(Vs), len(Vt))
    assert source == "file" and truth.shape == (len(Vs),)
    np.testing.assert_array_equal(truth, np.loadtxt(out / "ground_truth/mesh002.txt", dtype=np.int64))
    lm_ids, names = read_landmarks(out / "landmark_vids.txt", n_vertices=len(Vs))
    own, lm_source = target_landmarks(str(out), "mesh002", names, lm_ids, len(Vt))
    assert lm_source == "own"

    from bench.remesh_scape import sqrt_area
    scale = sqrt_area(Vt, Ft)
    gap = np.linalg.norm(Vt[truth[lm_ids]] - Vt[own], axis=1) / scale
    bound = 2 * info["mesh000"]["template_snap"][1] + info["mesh002"]["pose_snap"][1] + \
        info["mesh002"]["landmark_snap"][1]
    assert gap.max() <= bound, (gap.max(), bound)
    assert bound < 0.1                                     # the snaps are small next to the body
    on_pose = lm_ids < len(Vt)                             # the template's ids taken as the pose's: far off
    assert np.median(np.linalg.norm(Vt[lm_ids[on_pose]] - Vt[own[on_pose]], axis=1) / scale) > 5 * bound

    _, sparse_names = read_landmarks(out / "sparse_landmark_vids.txt", n_vertices=len(Vs))
    pairs = sparse_pairs(names, sparse_names, lm_ids, own)
    assert pairs.shape == (5, 2)
    np.testing.assert_array_equal(pairs[:, 1], [own[names.index(n)] for n in sparse_names])


@pytest.mark.course
def test_the_true_map_scores_near_zero_and_identity_is_refused(remeshed):
    from bench.correspondence import true_map
    from corr_core.correspondence.dense import measures

    out, _ = remeshed
    Vs, _ = _mesh(out / "meshes/template/mesh000.obj")
    Vt, Ft = _mesh(out / "meshes/test/mesh002.obj")
    truth, _ = true_map(str(out), "mesh002", len(Vs), len(Vt))
    vertices = np.arange(0, len(Vs), 97)
    errs = measures.dense_errors(Vt, Ft, {"truth": truth, "shifted": np.roll(truth, 1)}, truth, vertices=vertices)
    assert errs["truth"].max() == 0 and errs["shifted"].mean() > 0.1      # shuffled ids: a neighbour id is far
    with pytest.raises(ValueError, match="cannot be the ground truth"):
        true_map(str(out / "nowhere"), "mesh002", len(Vs), len(Vt))


def test_an_output_folder_it_did_not_make_is_refused(tmp_path):
    from bench.remesh_scape import prepare_out

    (tmp_path / "mine.txt").write_text("keep me")
    with pytest.raises(SystemExit, match="not written by"):
        prepare_out(str(tmp_path))
    assert (tmp_path / "mine.txt").read_text() == "keep me"
    made = tmp_path / "made"
    prepare_out(str(made))
    (made / "old.txt").write_text("from the last run")
    prepare_out(str(made))                                    # its own folder: emptied and written again
    assert [p.name for p in made.iterdir()] == [".made_by_remesh_scape"]


def test_pyfm_gets_its_landmark_pairs_target_first(monkeypatch):
    """run_pyfm takes (template id, target id) pairs; pyFM's FunctionalMapping(target, template) reads column 0
    on the target (its mesh1) and column 1 on the template (stand-in pyFM modules record the call)."""
    import sys
    import types

    from bench.correspondence import run_pyfm

    seen = {}

    class Model:
        def __init__(self, mesh1, mesh2):
            seen["meshes"] = (mesh1, mesh2)

        def preprocess(self, **kw):
            seen["landmarks"] = kw["landmarks"]

        def fit(self, **kw):
            pass

        def zoomout_refine(self, **kw):
            return "C"

        def get_p2p(self, FM):
            return np.arange(3)

    functional = types.SimpleNamespace(FunctionalMapping=Model)
    mesh = types.SimpleNamespace(TriMesh=lambda path, **kw: f"target {path}")
    monkeypatch.setitem(sys.modules, "pyFM", types.SimpleNamespace(functional=functional, mesh=mesh))
    monkeypatch.setitem(sys.modules, "pyFM.functional", functional)
    monkeypatch.setitem(sys.modules, "pyFM.mesh", mesh)
    run_pyfm("template", "t.obj", landmarks=np.array([[10, 1], [20, 2]]))
    assert seen["meshes"] == ("target t.obj", "template")
    np.testing.assert_array_equal(seen["landmarks"], [[1, 10], [2, 20]])
    run_pyfm("template", "t.obj")
    assert seen["landmarks"] is None


@pytest.mark.course
def test_the_exact_map_of_same_triangles_is_vertex_i_to_i():
    """exact_map (the --floor reference) on the course meshes themselves: a vertex's closest surface point is
    itself, carried to the same vertex of the pose."""
    from bench.remesh_scape import exact_map

    Vs, Fs = _mesh(SCAPE / "meshes/template/mesh000.obj")
    Vt, _ = _mesh(SCAPE / "meshes/test/mesh002.obj")
    some = np.arange(0, len(Vs), 7)
    np.testing.assert_array_equal(exact_map(Vs[some], Vs, Fs, Vt, Vt), some)


def test_runs_are_merged_on_their_common_pairs_and_flips_listed():
    from bench.correspondence import flip_lines, merged_rows

    def run(method, accs, seconds):
        return {"pairs": [{"mesh": m, method: {"landmark_accuracy": a}} for m, a in accs.items()],
                "template_seconds": seconds}

    rows, template_seconds = merged_rows([run("dense_auto", {"mesh002": 1.0, "mesh004": 0.25}, {"dense": 2.0}),
                                          run("pyfm_none", {"mesh004": 0.4, "mesh005": 1.0}, {"pyfm": 1.0})])
    assert rows == [{"mesh": "mesh004", "dense_auto": {"landmark_accuracy": 0.25},
                     "pyfm_none": {"landmark_accuracy": 0.4}}]
    assert template_seconds == {"dense": 2.0, "pyfm": 1.0}
    assert flip_lines(rows, ["dense_auto", "pyfm_none"])[1:] == ["  dense_auto: 1 (mesh004 0.25)",
                                                                 "  pyfm_none: 1 (mesh004 0.40)"]


def test_relative_lines_give_ratios_and_differences():
    from bench.correspondence import relative_lines

    def means(err, acc, w05, w25, sec):
        return {"mean_error": err, "landmark_accuracy": acc, "within_0.05": w05, "within_0.25": w25, "seconds": sec}

    lines = relative_lines({"dense_auto": means(0.011, 0.95, 0.98, 1.0, 5.0), "pyfm_none": means(1, 1, 1, 1, 1)},
                           {"dense_auto": means(0.010, 1.0, 0.99, 1.0, 10.0)}, "base.json")
    assert lines[0].startswith("relative to base.json")
    assert lines[1:] == ["  dense_auto    mean err x1.100  s/pair x0.500  lm acc -0.0500  <=0.05 -0.010  "
                         "<=0.25 +0.000"]


@pytest.mark.course
def test_a_carried_map_of_same_triangles_is_the_map_itself():
    """carried_map (the --carry reference) on the course meshes themselves: a vertex's closest surface point is
    itself, so any map between them comes back unchanged (a permutation, not only the identity of exact_map);
    a map with no image for a needed vertex is refused."""
    from bench.remesh_scape import carried_map

    Vs, Fs = _mesh(SCAPE / "meshes/template/mesh000.obj")
    Vt, _ = _mesh(SCAPE / "meshes/test/mesh002.obj")
    p2p = np.random.default_rng(0).permutation(len(Vs))
    some = np.arange(0, len(Vs), 7)
    np.testing.assert_array_equal(carried_map(Vs[some], Vs, Fs, p2p, Vt, Vt), p2p[some])
    p2p[some[3]] = -1
    with pytest.raises(ValueError, match="no pose vertex"):
        carried_map(Vs[some], Vs, Fs, p2p, Vt, Vt)


def test_against_lines_compare_a_run_with_the_carried_errors_on_shared_poses(tmp_path):
    import json

    from bench.remesh_scape import against_lines

    run = {"pairs": [{"mesh": "mesh002", "dense_auto": {"mean_error": 0.012}},
                     {"mesh": "mesh004", "dense_auto": {"mean_error": 0.010}}]}
    (tmp_path / "rem.json").write_text(json.dumps(run))
    carried = {"exact": {"mesh002": 0.002}, "dense_auto": {"mesh002": 0.010, "mesh005": 0.5},
               "dense_sparse": {"mesh002": 0.01}}
    assert against_lines(carried, [str(tmp_path / "rem.json")]) == [
        "dense_auto: 0.01200 in rem.json / carried 0.01000 = x1.200, carried / run x0.833 (1 poses)"]


def test_carry_refuses_a_missing_maps_folder_or_a_set_it_did_not_write(tmp_path):
    from bench.remesh_scape import main

    with pytest.raises(SystemExit, match="no such folder of maps"):
        main(["--carry", str(tmp_path / "nowhere"), "--out", str(tmp_path)])
    (tmp_path / "maps").mkdir()
    with pytest.raises(SystemExit, match="no remeshed set written by"):
        main(["--carry", str(tmp_path / "maps"), "--out", str(tmp_path)])
