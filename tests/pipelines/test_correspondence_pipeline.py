"""Problem 2 through the engine: landmark correspondence on the generated humanoid, partial reruns, bad input.

All tests share one cache (module fixture), so each test computes only what its own changes make new.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from corr_core.generate.humanoid import write_humanoid_dataset
from corr_core.correspondence.landmarks import read_landmarks, write_landmarks
from corr_core.geometry.checks import check_correspondence_mesh
from corr_core.geometry.mesh_io import load_mesh, save_obj
from shapecorr.correspondence import mesh as corr_mesh
from stages import api

from tests.helpers import COURSE_DATA, logged

N_POSES = 3
TESTS = [f"mesh{i:03d}" for i in range(1, N_POSES + 1)]
N_LANDMARKS, N_SPARSE, DENSE_POINTS = 20, 5, 20
METHODS = ["descriptor", "descriptor_sparse", "mrf", "mrf_sparse", "mrf_oriented", "mrf_oriented_sparse",
           "mobius_sparse", "mobius_all"]
# measured on this dataset (3 poses, seed 0): mrf_oriented 28/30 = 0.933, mrf_oriented_sparse 15/15
MRF_ORIENTED_FLOOR = 0.85
MRF_ORIENTED_SPARSE_FLOOR = 0.8
CORR_STAGES = ["mesh", "spectral", "geodesics", "flatten", "descriptor", "mrf", "mrf_oriented", "mobius",
               "evaluate"]

PIPE = """\
name: corr_test
params:
  data: {{root: "{root}"}}
  template: mesh000
  sigma: 0.05
  K: 0.5
datasets:
  meshes: {{files: "${{data.root}}/meshes/*/*.obj"}}
  tests: {{files: "${{data.root}}/meshes/test/*.obj"}}
  landmarks: {{file: "${{data.root}}/landmark_vids.txt"}}
  sparse_landmarks: {{file: "${{data.root}}/sparse_landmark_vids.txt"}}
  flattened: {{folder: "${{data.root}}/flattened_meshes", optional: true}}
  uniform_samples: {{file: "${{data.root}}/uniform_sample_vids.txt", optional: true}}
stages:
  mesh: {{function: corr.mesh, foreach: meshes, inputs: {{path: meshes}}}}
  spectral: {{function: corr.spectral, foreach: mesh, inputs: {{mesh: mesh, landmarks: landmarks}}, params: {{k: 40}}}}
  geodesics: {{function: corr.geodesics, foreach: mesh, inputs: {{mesh: mesh, landmarks: landmarks}}}}
  flatten:
    function: corr.flatten
    foreach: mesh
    inputs: {{mesh: mesh, path: meshes, landmarks: landmarks, flattened: flattened, samples: uniform_samples}}
    params: {{n_samples: 150}}
  descriptor:
    function: corr.match_descriptor
    foreach: tests
    inputs: {{template: "spectral[${{template}}]", target: spectral, landmarks: landmarks,
             sparse_landmarks: sparse_landmarks}}
  mrf:
    function: corr.match_mrf
    foreach: tests
    inputs: {{template: "geodesics[${{template}}]", target: geodesics, landmarks: landmarks,
             sparse_landmarks: sparse_landmarks}}
    params: {{sigma: "${{sigma}}"}}
  mrf_oriented:
    function: corr.match_mrf
    foreach: tests
    inputs: {{template: "geodesics[${{template}}]", target: geodesics, landmarks: landmarks,
             sparse_landmarks: sparse_landmarks}}
    params: {{sigma: "${{sigma}}", orientation: true}}
  mobius:
    function: corr.match_mobius
    foreach: tests
    inputs: {{template: "flatten[${{template}}]", target: flatten, template_mesh: "mesh[${{template}}]",
             target_mesh: mesh, landmarks: landmarks, sparse_landmarks: sparse_landmarks}}
    params: {{K: "${{K}}", dense_points: {dense_points}}}
  evaluate:
    function: corr.evaluate
    inputs: {{landmarks: landmarks, sparse_landmarks: sparse_landmarks, descriptor: "descriptor[*]",
             mrf: "mrf[*]", mrf_oriented: "mrf_oriented[*]", mobius_votes: "mobius[*]"}}
    metrics: true
"""


@pytest.fixture(scope="module")
def humanoid(tmp_path_factory):
    """The generated dataset (template + 3 poses) and a cache shared by every test of this module."""
    tmp = tmp_path_factory.mktemp("corr")
    info = write_humanoid_dataset(tmp / "humans", n_poses=N_POSES, seed=0)
    return {"data": tmp / "humans", "cache": tmp / "cache", "info": info}


class Project:
    """A pipeline file in its own folder over a data folder, with the module's shared cache."""

    def __init__(self, folder: Path, data: Path, cache: Path, client):
        self.folder, self.cache, self.client = folder, cache, client
        self.pipe = folder / "p.yaml"
        self.pipe.write_text(PIPE.format(root=data.as_posix(), dense_points=DENSE_POINTS))
        self.out = folder / "results"

    def run(self, sets=()):
        return api.run(str(self.pipe), list(sets), client_getter=lambda: self.client, quiet=True,
                          cache_dir=str(self.cache), output_dir=str(self.out))

    def metrics(self, sets=()):
        return api.metrics(api.plan_pipeline(str(self.pipe), list(sets), cache_dir=str(self.cache),
                                                   output_dir=str(self.out), quiet=True))


def _project(tmp_path, humanoid, client, copy_data=False) -> Project:
    data = humanoid["data"]
    if copy_data:
        data = tmp_path / "humans"
        shutil.copytree(humanoid["data"], data)
    return Project(tmp_path, data, humanoid["cache"], client)


def _executed(summary) -> dict[str, int]:
    return {name: s["executed"] for name, s in summary["stages"].items()}


# --------------------------------------------------------------------------------------------------------------
# 1. end to end


def test_end_to_end_on_generated_humanoid(tmp_path, humanoid, dask_client):
    p = _project(tmp_path, humanoid, dask_client)
    s = p.run()
    assert not s["failures"]
    assert {n: s["stages"][n]["tasks"] for n in CORR_STAGES} == {
        "mesh": N_POSES + 1, "spectral": N_POSES + 1, "geodesics": N_POSES + 1, "flatten": N_POSES + 1,
        "descriptor": N_POSES, "mrf": N_POSES, "mrf_oriented": N_POSES, "mobius": N_POSES, "evaluate": 1}
    m = p.metrics()
    acc = m["accuracy"]
    assert set(acc) == set(METHODS)
    assert all(0.0 <= v <= 1.0 for v in acc.values())
    assert acc["mrf_oriented"] >= MRF_ORIENTED_FLOOR, acc
    assert acc["mrf_oriented_sparse"] >= MRF_ORIENTED_SPARSE_FLOOR, acc
    assert set(m["accuracy_per_mesh"]["mrf"]) == set(TESTS)

    out = p.out / "evaluate"
    corr = json.loads((out / "correspondences.json").read_text())
    assert corr["landmarks"] == read_landmarks(humanoid["data"] / "landmark_vids.txt")[1]
    assert corr["sparse_landmarks"] == list(humanoid["info"]["sparse_landmarks"])
    assert set(corr["matrices"]) == set(METHODS)
    for method, per_mesh in corr["matrices"].items():
        n = N_SPARSE if method.endswith("sparse") else N_LANDMARKS
        assert set(per_mesh) == set(TESTS), method
        diag = []
        for mat in per_mesh.values():
            M = np.asarray(mat)
            assert M.shape == (n, n) and set(np.unique(M)) <= {0, 1}
            assert np.all(M.sum(axis=1) == 1), method  # one target landmark per template landmark
            diag.append(np.trace(M) / n)
        # the reported accuracy is the fraction of i -> i entries of these matrices (truth: landmark i -> i)
        assert acc[method] == pytest.approx(np.mean(diag)), method
        assert m["accuracy_per_mesh"][method] == pytest.approx(
            {k: np.trace(np.asarray(v)) / n for k, v in per_mesh.items()})

    for name in [f"frequency_{mth}.png" for mth in METHODS] + ["accuracy.png", "dense_map_error_curve.png"]:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert m["dense_map"]["n_points"] == N_POSES * DENSE_POINTS
    assert "dense_map_skipped" not in m


# --------------------------------------------------------------------------------------------------------------
# 2. partial reruns


def test_changing_sigma_or_K_reruns_only_the_matching_that_uses_it(tmp_path, humanoid, dask_client):
    p = _project(tmp_path, humanoid, dask_client)
    p.run()
    assert sum(_executed(p.run()).values()) == 0  # nothing changed: nothing runs

    zero = dict.fromkeys(CORR_STAGES, 0)
    s = p.run(["sigma=0.1"])  # shared by mrf and mrf_oriented
    assert _executed(s) == zero | {"mrf": N_POSES, "mrf_oriented": N_POSES, "evaluate": 1}
    assert s["stages"]["mesh"]["cached"] == N_POSES + 1 and s["stages"]["geodesics"]["cached"] == N_POSES + 1
    s = p.run(["mrf.sigma=0.2"])  # one stage's parameter only
    assert _executed(s) == zero | {"mrf": N_POSES, "evaluate": 1}
    s = p.run(["K=0.3"])
    assert _executed(s) == zero | {"mobius": N_POSES, "evaluate": 1}
    for sets in (["sigma=0.1"], ["mrf.sigma=0.2"], ["K=0.3"]):
        assert all(0.0 <= v <= 1.0 for v in p.metrics(sets)["accuracy"].values())


# --------------------------------------------------------------------------------------------------------------
# 3. bad input


def test_landmark_id_out_of_range_fails_naming_file_line_and_id(tmp_path, humanoid, dask_client):
    p = _project(tmp_path, humanoid, dask_client, copy_data=True)
    lm = tmp_path / "humans" / "landmark_vids.txt"
    lines = lm.read_text().splitlines()
    bad_id = humanoid["info"]["n_vertices"] + 7
    lines[2] = f"{bad_id},{lines[2].split(',', 1)[1]}"
    lm.write_text("\n".join(lines) + "\n")
    with pytest.raises(api.RunFailed) as info:
        p.run()
    s = info.value.summary
    failed = {(f["stage"], f["item"]) for f in s["failures"]}
    assert failed == {(st, it) for st in ("spectral", "geodesics", "flatten") for it in ["mesh000"] + TESTS}
    for f in s["failures"]:
        assert "landmark_vids.txt:3" in f["error"] and str(bad_id) in f["error"] and "out of range" in f["error"]
    assert s["stages"]["mesh"]["failed"] == 0
    assert s["stages"]["evaluate"]["executed"] == 0 and s["stages"]["descriptor"]["executed"] == 0


def _split_face(V, F, f=0):
    """A new vertex at the centroid of face f, which becomes 3 faces: n+1 vertices, ids 0..n-1 unchanged."""
    a, b, c = F[f]
    n = len(V)
    F2 = np.concatenate([np.delete(F, f, axis=0), [[a, b, n], [b, c, n], [c, a, n]]])
    return np.concatenate([V, V[[a, b, c]].mean(axis=0, keepdims=True)]), F2


def _flip_one_edge(V, F):
    """Flip one interior edge (same vertices, different connectivity), checked to stay a valid mesh."""
    for f in range(len(F)):
        a, b, c = F[f]
        g = np.flatnonzero((F[:, 1] == a) & (F[:, 0] == b) | (F[:, 2] == a) & (F[:, 1] == b)
                           | (F[:, 0] == a) & (F[:, 2] == b))
        if len(g) != 1:
            continue
        d = int(np.setdiff1d(F[g[0]], [a, b])[0])
        F2 = F.copy()
        F2[f], F2[g[0]] = [c, a, d], [d, b, c]
        try:
            check_correspondence_mesh(V, F2)
        except Exception:
            continue
        return F2
    raise AssertionError("no flippable edge")


def test_only_the_template_triangles_keep_the_landmark_truth(tmp_path, humanoid, dask_client):
    """Vertex ids name the same points only on a mesh with the template's triangles: a vertex
    count never decides. A face split (one vertex more), one flipped edge or shuffled vertex ids (same counts)
    lose the truth; faces reordered or 2 unused vertices appended keep it."""
    p = _project(tmp_path, humanoid, dask_client, copy_data=True)
    test_dir = tmp_path / "humans" / "meshes" / "test"
    n = humanoid["info"]["n_vertices"]
    V, F = load_mesh(test_dir / "mesh003.obj")
    save_obj(test_dir / "mesh003.obj", *_split_face(V, F))  # one vertex more; landmark ids still valid
    V, F = load_mesh(test_dir / "mesh002.obj")
    save_obj(test_dir / "mesh002.obj", V, _flip_one_edge(V, F))  # same vertex count, other faces
    V, F = load_mesh(test_dir / "mesh001.obj")
    save_obj(test_dir / "mesh001.obj", V, F[np.random.default_rng(0).permutation(len(F))])  # same connectivity
    save_obj(test_dir / "mesh004.obj", np.concatenate([V, V[:2] + 5.0]), F)  # 2 unused vertices appended
    perm = np.random.default_rng(1).permutation(len(V))                      # new id of vertex j: perm[j]
    save_obj(test_dir / "mesh005.obj", V[np.argsort(perm)], perm[F])        # same counts, ids shuffled
    s = p.run()
    assert not s["failures"]
    m = p.metrics()
    for method in METHODS:
        assert set(m["accuracy_per_mesh"][method]) == {"mesh001", "mesh004"}
    assert set(m["not_scored"]) == {"mesh002", "mesh003", "mesh005"}
    assert f"{n + 1} vertices / {len(F) + 2} faces vs the template's {n} / {len(F)}" in m["not_scored"]["mesh003"]
    for same_counts in ("mesh002", "mesh005"):
        assert "same counts, another vertex order" in m["not_scored"][same_counts]
    assert m["accuracy_per_mesh"]["mrf_oriented"]["mesh004"] == m["accuracy_per_mesh"]["mrf_oriented"]["mesh001"]
    # vertex i <-> vertex i is only true with the template's triangles: the others are left out, with a note
    skipped = m["dense_map_skipped"]
    assert set(skipped) == {"mesh002", "mesh003", "mesh005"}
    assert f"{n + 1} vertices" in skipped["mesh003"] and "same triangles" in skipped["mesh003"]
    assert m["dense_map"]["n_points"] == 2 * DENSE_POINTS  # mesh001 (faces reordered) and mesh004 are measured


def _nonmanifold(V, F):
    """One more face on an existing edge (3 faces share it), its third vertex off the surface."""
    a, b, c = F[0]
    p = (V[a] + V[b]) / 2 + 0.5 * (V[a] + V[b] - 2 * V[c])
    return np.concatenate([V, [p]]), np.concatenate([F, [[b, a, len(V)]]])


def _degenerate(V, F):
    """Face 0 gets zero area: its third vertex is moved onto its first."""
    V = V.copy()
    V[F[0, 2]] = V[F[0, 0]]
    return V, F


def _two_components(V, F):
    """A small closed tetrahedron added next to the body."""
    T = np.array([[2.0, 0, 0], [2.1, 0, 0], [2.0, 0.1, 0], [2.0, 0, 0.1]])
    tets = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]) + len(V)
    return np.concatenate([V, T]), np.concatenate([F, tets])


def test_bad_meshes_fail_by_name_and_the_others_are_kept(tmp_path, humanoid, dask_client):
    p = _project(tmp_path, humanoid, dask_client, copy_data=True)
    p.run()
    test_dir = tmp_path / "humans" / "meshes" / "test"
    V, F = load_mesh(test_dir / "mesh001.obj")
    V_nan = V.copy()
    V_nan[F[0, 0]] = np.nan
    bad = {"bad_nan": ((V_nan, F), "NaN or infinite coordinate")}
    # repaired on load (a fin is kept with a warning, zero-area faces are dropped, the largest component is
    # kept for the intrinsic methods): these items run
    repairable = {"bad_nonmanifold": _nonmanifold(V, F), "bad_degenerate": _degenerate(V, F),
                  "bad_components": _two_components(V, F)}
    for name, (Vb, Fb) in {**{k: v for k, (v, _) in bad.items()}, **repairable}.items():
        save_obj(test_dir / f"{name}.obj", Vb, Fb)
    with pytest.raises(api.RunFailed) as info:
        p.run()
    s = info.value.summary
    failures = {f["item"]: f for f in s["failures"]}
    assert set(failures) == set(bad)
    for name, (_, problem) in bad.items():
        assert failures[name]["stage"] == "mesh"
        assert f"{name}.obj" in failures[name]["error"] and problem in failures[name]["error"]
    st = s["stages"]
    assert st["mesh"]["failed"] == 1 and st["mesh"]["cached"] == N_POSES + 1 and st["mesh"]["executed"] == 3
    for name in ("spectral", "geodesics", "flatten"):
        assert st[name]["cached"] == N_POSES + 1 and st[name]["skipped"] == 1, name
    for name in ("descriptor", "mrf", "mrf_oriented", "mobius"):
        assert st[name]["cached"] == N_POSES and st[name]["skipped"] == 1, name
    # once the bad files are gone, everything per mesh comes from the cache
    for name in [*bad, *repairable]:
        (test_dir / f"{name}.obj").unlink()
    s = p.run()
    assert sum(_executed(s).values()) == 0


N_UNUSED = 10


def _loose_piece_and_unused_vertices(V, F):
    """The mesh with 10 unreferenced vertices spread among the ids (far away) and a small closed tetrahedron
    appended (a loose piece). Returns V2, F2 and new_id: (n,) int id in V2 of each original vertex."""
    n = len(V)
    unused_at = np.linspace(0, n, N_UNUSED, endpoint=False).astype(np.int64)  # before original vertex unused_at
    new_id = np.arange(n) + np.searchsorted(unused_at, np.arange(n), side="right")
    V2 = np.full((n + N_UNUSED, 3), 50.0)
    V2[new_id] = V
    T = V.max(axis=0) + np.array([[0.3, 0, 0], [0.35, 0, 0], [0.3, 0.05, 0], [0.3, 0, 0.05]])
    tets = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]) + len(V2)
    return np.concatenate([V2, T]), np.concatenate([new_id[F], tets]), new_id


def _remap_landmark_file(path: Path, new_id: np.ndarray) -> None:
    ids, names = read_landmarks(path)
    write_landmarks(path, new_id[ids], names)


def _dirty_copy(tmp_path, humanoid) -> tuple[Path, np.ndarray]:
    """A copy of the dataset where every mesh has a loose piece and unused vertices (landmarks renumbered)."""
    data = tmp_path / "humans"
    shutil.copytree(humanoid["data"], data)
    for path in sorted((data / "meshes").glob("*/*.obj")):
        V2, F2, new_id = _loose_piece_and_unused_vertices(*load_mesh(path))
        save_obj(path, V2, F2)
    for name in ("landmark_vids.txt", "sparse_landmark_vids.txt"):
        _remap_landmark_file(data / name, new_id)
    return data, new_id


def test_loose_piece_and_unused_vertices_give_the_clean_results(tmp_path, humanoid, dask_client):
    """Every method runs on the largest component, in the original vertex ids: the same landmark predictions,
    accuracies and dense-map errors as on the clean meshes."""
    (tmp_path / "clean").mkdir()
    clean = _project(tmp_path / "clean", humanoid, dask_client)
    clean.run()
    data, _ = _dirty_copy(tmp_path, humanoid)
    dirty = Project(tmp_path, data, humanoid["cache"], dask_client)
    s = dirty.run()
    assert not s["failures"] and s["stages"]["mesh"]["executed"] == N_POSES + 1
    m, m0 = dirty.metrics(), clean.metrics()
    assert set(m["accuracy"]) == set(METHODS) and "not_scored" not in m
    assert m["accuracy"] == m0["accuracy"] and m["accuracy_per_mesh"] == m0["accuracy_per_mesh"]
    corr = json.loads((dirty.out / "evaluate" / "correspondences.json").read_text())
    corr0 = json.loads((clean.out / "evaluate" / "correspondences.json").read_text())
    assert corr["matrices"] == corr0["matrices"]
    assert m["dense_map"] == m0["dense_map"]
    n = humanoid["info"]["n_vertices"]
    with logged() as messages:
        repairs = {r["kind"]: r for r in corr_mesh(str(data / "meshes" / "test" / "mesh001.obj"))["repairs"]}
    assert any("kept the largest of 2 components" in m for m in messages)
    assert f"kept the largest of 2 components: {n:,} of {n + 4:,} vertices; 4 vertices in 1 small piece " \
           "ignored" in repairs["components"]["message"]
    assert repairs["unreferenced_vertices"]["count"] == N_UNUSED


def test_landmark_on_a_loose_piece_fails_naming_the_landmark_and_the_file(tmp_path, humanoid, dask_client):
    data, new_id = _dirty_copy(tmp_path, humanoid)
    lm = data / "landmark_vids.txt"
    lines = lm.read_text().splitlines()
    name = lines[2].split(",", 1)[1]
    loose_vertex = humanoid["info"]["n_vertices"] + N_UNUSED + 1  # a tetrahedron vertex
    lines[2] = f"{loose_vertex},{name}"
    lm.write_text("\n".join(lines) + "\n")
    p = Project(tmp_path, data, humanoid["cache"], dask_client)
    with pytest.raises(api.RunFailed) as info:
        p.run()
    s = info.value.summary
    assert {(f["stage"], f["item"]) for f in s["failures"]} == {
        (st, it) for st in ("spectral", "geodesics", "flatten") for it in ["mesh000"] + TESTS}
    for f in s["failures"]:
        assert f"landmark {name!r} (vertex {loose_vertex}) from landmark_vids.txt on {f['item']}.obj" in f["error"]
        assert "largest connected component" in f["error"]


# --------------------------------------------------------------------------------------------------------------
# 4. course data


COURSE_PIPE = """\
name: corr_course
params:
  data: {{root: "{root}"}}
  template: mesh000
datasets:
  meshes: {{files: "${{data.root}}/meshes/*/*.obj"}}
  tests: {{files: "${{data.root}}/meshes/test/*.obj"}}
  landmarks: {{file: "${{data.root}}/landmark_vids.txt"}}
  sparse_landmarks: {{file: "${{data.root}}/sparse_landmark_vids.txt"}}
stages:
  mesh: {{function: corr.mesh, foreach: meshes, inputs: {{path: meshes}}}}
  spectral: {{function: corr.spectral, foreach: mesh, inputs: {{mesh: mesh, landmarks: landmarks}}, params: {{k: 30}}}}
  descriptor:
    function: corr.match_descriptor
    foreach: tests
    inputs: {{template: "spectral[${{template}}]", target: spectral, landmarks: landmarks,
             sparse_landmarks: sparse_landmarks}}
  evaluate:
    function: corr.evaluate
    inputs: {{landmarks: landmarks, sparse_landmarks: sparse_landmarks, descriptor: "descriptor[*]"}}
    metrics: true
"""


@pytest.mark.course
def test_course_scape_descriptor_accuracy_on_three_poses(tmp_path, dask_client):
    """Cheap stages only (mesh check, HKS+WKS from 30 eigenpairs, Hungarian) on 3 SCAPE test poses.

    Measured: descriptor 23/30 = 0.767 (k = 30 and k = 100 alike), descriptor_sparse 13/15 = 0.867.
    """
    src = COURSE_DATA / "scape"
    data = tmp_path / "scape"
    (data / "meshes" / "template").mkdir(parents=True)
    (data / "meshes" / "test").mkdir(parents=True)
    (data / "meshes" / "template" / "mesh000.obj").symlink_to(src / "meshes" / "template" / "mesh000.obj")
    for name in ("mesh002", "mesh004", "mesh005"):
        (data / "meshes" / "test" / f"{name}.obj").symlink_to(src / "meshes" / "test" / f"{name}.obj")
    for name in ("landmark_vids.txt", "sparse_landmark_vids.txt"):
        (data / name).symlink_to(src / name)
    pipe = tmp_path / "p.yaml"
    pipe.write_text(COURSE_PIPE.format(root=data.as_posix()))
    kw = dict(cache_dir=str(tmp_path / "cache"), output_dir=str(tmp_path / "results"), quiet=True)
    s = api.run(str(pipe), client_getter=lambda: dask_client, **kw)
    assert s["stages"]["spectral"]["tasks"] == 4 and not s["failures"]
    m = api.metrics(api.plan_pipeline(str(pipe), **kw))
    assert set(m["accuracy"]) == {"descriptor", "descriptor_sparse"}
    assert m["accuracy"]["descriptor"] >= 0.65, m["accuracy"]
    assert m["accuracy"]["descriptor_sparse"] >= 0.6, m["accuracy"]
    corr = json.loads((tmp_path / "results" / "evaluate" / "correspondences.json").read_text())
    assert set(corr["matrices"]["descriptor"]) == {"mesh002", "mesh004", "mesh005"}
