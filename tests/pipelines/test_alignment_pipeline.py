"""Problem 1 through the engine: generated chairs with known azimuths, exports, figures, bad input."""
from __future__ import annotations

import csv
import json
import os
import re
import shutil

import numpy as np
import pytest
from PIL import Image

from corr_core.generate import write_chair_collection
from stages import api

from tests.helpers import ROOT, COURSE_DATA


PIPE = """\
name: align_test
params:
  data: {root: chairs}
  solver: spectral
datasets:
  shapes:
    groups: "${data.root}/*"
    pattern: '(?P<item>[^_/]+?)(?:_(?P<index>\\d+))?\\.(?:png|obj|off|ply)'
  ground_truth: {file: "${data.root}/ground_truth.csv", optional: true}
stages:
  views: {function: align.views, foreach: shapes, inputs: {files: shapes}, params: {image_size: 96}}
  hog: {function: align.hog, foreach: views, inputs: {views: views}}
  pairs: {function: align.pair_costs, pairs: hog, tile: 4}
  solve: {function: align.solve, inputs: {costs: pairs}, params: {solver: "${solver}"}}
  evaluate:
    function: align.evaluate
    inputs: {costs: pairs, solution: solve, ground_truth: ground_truth}
    params: {seeds: [0, 1], restarts: 3}
    metrics: true
  export: {function: align.export, inputs: {shapes: shapes, solution: solve}}
  figures:
    function: align.figures
    inputs: {views: "views[*]", features: "hog[*]", costs: pairs, solution: solve}
"""


@pytest.fixture(scope="module")
def chairs_project(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("align")
    write_chair_collection(tmp / "chairs", n=10, seed=3)
    (tmp / "p.yaml").write_text(PIPE)
    return tmp


def _run(tmp, client, sets=()):
    cwd = os.getcwd()
    os.chdir(tmp)
    try:
        return api.run("p.yaml", list(sets), client_getter=lambda: client, quiet=True)
    finally:
        os.chdir(cwd)


def _metrics(tmp, sets=()):
    cwd = os.getcwd()
    os.chdir(tmp)
    try:
        return api.metrics(api.plan_pipeline("p.yaml", list(sets), quiet=True))
    finally:
        os.chdir(cwd)


def test_generated_chairs_are_aligned_up_to_one_offset(chairs_project, dask_client):
    s = _run(chairs_project, dask_client)
    assert s["stages"]["views"]["executed"] == 10
    m = _metrics(chairs_project)
    assert m["ground_truth"]["exact"] == 1.0 and m["ground_truth"]["n"] == 10
    assert m["equivariance"] == 1.0
    assert set(m["labels"]) == {f"{i:03d}" for i in range(1, 11)}
    q = m["solver_quality"]
    assert q["random_labeling"] < q["energy"] <= q["upper_bound"]
    # the LH solver is selectable; only the MRF and what follows reruns
    s = _run(chairs_project, dask_client, ["solver=lh"])
    assert s["stages"]["views"]["executed"] == 0 and s["stages"]["pairs"]["executed"] == 0
    assert s["stages"]["solve"]["executed"] == 1
    assert _metrics(chairs_project, ["solver=lh"])["ground_truth"]["within_one_view"] >= 0.9


def test_exports_and_figures(chairs_project, dask_client):
    _run(chairs_project, dask_client)
    out = chairs_project / "results" / "align_test"
    rows = list(csv.DictReader(open(out / "export" / "alignment.csv")))
    m = _metrics(chairs_project)
    assert {r["shape"]: int(r["label"]) for r in rows} == m["labels"]
    objs = sorted((out / "export" / "aligned_meshes").glob("*.obj"))
    assert len(objs) == 10 and (out / "export" / "aligned_meshes.zip").is_file()
    # aligned meshes are normalized and rotated to a common frame: their x-z footprints agree
    from corr_core.geometry.mesh_io import load_mesh
    V1, _ = load_mesh(objs[0])
    assert np.linalg.norm(V1, axis=1).max() == pytest.approx(1.0, abs=1e-6)
    for name in ("hog_drawings.png", "dij_heatmap.png", "view_pairs_best_worst.png", "aligned_grid.png"):
        img = Image.open(out / "figures" / name)
        assert img.size[0] > 200 and img.size[1] > 200


def xz_rotation_deg(A: np.ndarray, B: np.ndarray) -> float:
    """Angle a (degrees) of the rotation about +y that best takes points A (n,3) onto B (n,3), rows matched."""
    return float(np.rad2deg(np.arctan2(np.sum(A[:, 2] * B[:, 0] - A[:, 0] * B[:, 2]),
                                       np.sum(A[:, 0] * B[:, 0] + A[:, 2] * B[:, 2]))))


def test_aligned_meshes_share_a_frame(chairs_project, dask_client):
    """Each aligned mesh is its canonical chair turned by one global rotation (the same for all, to within the
    continuous azimuths' error), and by nothing else."""
    _run(chairs_project, dask_client)
    out = chairs_project / "results" / "align_test" / "export" / "aligned_meshes"
    from corr_core.generate.chairs import canonical_chair
    from corr_core.geometry.mesh_io import load_mesh, normalize_mesh
    from corr_core.geometry.primitives import rotate_about_y
    angles = []
    for i in (1, 2, 3):
        Va, _ = load_mesh(out / f"{i:03d}.obj")
        Vc, Fc = canonical_chair(3, i)
        Vc, _, _ = normalize_mesh(Vc, center="area", F=Fc)
        a = xz_rotation_deg(Vc, Va)
        assert np.abs(rotate_about_y(Vc, np.deg2rad(a)) - Va).max() < 1e-5
        angles.append(a)
    spread = (np.array(angles) - angles[0] + 180.0) % 360.0 - 180.0
    assert np.abs(spread).max() < 2.0


def test_bad_meshes_are_reported_by_name_and_others_kept(tmp_path, dask_client):
    write_chair_collection(tmp_path / "chairs", n=5, seed=1)
    (tmp_path / "p.yaml").write_text(PIPE)
    _run(tmp_path, dask_client)
    text = (tmp_path / "chairs" / "003.obj").read_text().splitlines()
    i = next(k for k, l in enumerate(text) if l.startswith("v "))
    text[i] = "v nan 0 0"
    (tmp_path / "chairs" / "003.obj").write_text("\n".join(text) + "\n")
    (tmp_path / "chairs" / "006.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")  # no faces
    with pytest.raises(api.RunFailed) as info:
        _run(tmp_path, dask_client)
    failures = {f["item"]: f["error"] for f in info.value.summary["failures"]}
    assert set(failures) == {"003", "006"}
    assert "003.obj" in failures["003"] and "NaN" in failures["003"]
    assert "006.obj" in failures["006"] and "no faces" in failures["006"]
    assert info.value.summary["stages"]["views"]["cached"] == 4  # the untouched shapes were kept


def test_views_folder_with_a_missing_view_names_the_shape(tmp_path):
    folder = tmp_path / "views"
    folder.mkdir()
    for item in ("001", "002"):
        for v in range(16):
            if item == "002" and v == 4:
                continue
            Image.new("RGB", (30, 40), (0, 0, 255)).save(folder / f"{item}_{v}.png")
    (tmp_path / "p.yaml").write_text(PIPE)
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:  # an item failure of that shape (tests/stages/test_failed_items.py), not a pipeline error
        plan = api.plan_pipeline("p.yaml", ["data.root=views"], quiet=True)
        assert re.search(r"item '002' is missing parts \[4\]", plan.datasets["shapes"].items["002"].error)
        assert plan.datasets["shapes"].items["001"].error == ""
    finally:
        os.chdir(cwd)


@pytest.mark.course
def test_course_views_subset_is_equivariant(tmp_path, dask_client):
    folder = tmp_path / "views"
    folder.mkdir()
    for item in [f"{i:03d}" for i in range(1, 13)]:
        for v in range(16):
            shutil.copy(COURSE_DATA / "chairs_rendering" / f"{item}_{v}.png", folder / f"{item}_{v}.png")
    (tmp_path / "p.yaml").write_text(PIPE.replace("image_size: 96", "image_size: 120"))
    _run(tmp_path, dask_client, ["data.root=views"])
    m = _metrics(tmp_path, ["data.root=views"])
    assert m["equivariance"] == 1.0 and m["seed_stability"]["min"] == 1.0
    assert "ground_truth" not in m
    out = tmp_path / "results" / "align_test" / "export"
    assert len(list((out / "aligned_views").glob("*.png"))) == 12


def test_the_aligned_meshes_archive_is_the_same_bytes_whenever_its_files_were_written(tmp_path):
    """Same results, bit for bit: the zip carries no file times (two runs' archives once differed while their
    contents were equal); it holds every file under the folder's name, in name order."""
    import zipfile

    from shapecorr.alignment import _zip_folder

    folder = tmp_path / "aligned_meshes"
    folder.mkdir()
    for name, text in (("b.obj", "v 0 0 0\n"), ("a.obj", "v 1 0 0\n")):
        (folder / name).write_text(text)
    archives = []
    for when in (1_000_000_000, 1_700_000_000):           # 2001 and 2023
        for f in folder.iterdir():
            os.utime(f, (when, when))
        _zip_folder(str(folder))
        archives.append((tmp_path / "aligned_meshes.zip").read_bytes())
    assert archives[0] == archives[1]
    with zipfile.ZipFile(tmp_path / "aligned_meshes.zip") as z:
        assert z.namelist() == ["aligned_meshes/a.obj", "aligned_meshes/b.obj"]
        assert z.read("aligned_meshes/a.obj") == b"v 1 0 0\n"
