"""pipelines/tables.yaml through the engine (smaller): generated tables of known symmetry mixed with chairs at
continuous azimuths -> symmetry orders, continuous angles in the metrics, alignment.csv and the exported OBJs."""
from __future__ import annotations

import csv
import os

import numpy as np
import pytest

from stages import api

from tests.helpers import ROOT


@pytest.fixture(scope="module")
def tables_project(tmp_path_factory):
    """pipelines/tables.yaml with 6 tables and 4 chairs, run once in a temporary folder."""
    tmp = tmp_path_factory.mktemp("tables")
    text = (ROOT / "pipelines" / "tables.yaml").read_text()
    text = text.replace("params: {n: 12, n_chairs: 12,", "params: {n: 6, n_chairs: 4,")
    assert "n: 6, n_chairs: 4" in text
    (tmp / "p.yaml").write_text(text)
    return tmp


def _in(tmp, fn):
    cwd = os.getcwd()
    os.chdir(tmp)
    try:
        return fn()
    finally:
        os.chdir(cwd)


def test_symmetry_orders_and_continuous_angles(tables_project, dask_client):
    _in(tables_project, lambda: api.run("p.yaml", [], client_getter=lambda: dask_client, quiet=True))
    m = _in(tables_project, lambda: api.metrics(api.plan_pipeline("p.yaml", [], quiet=True)))
    root = next((tables_project / "cache" / "generated").glob("*/ground_truth.csv")).parent
    truth = {r["shape"]: r for r in csv.DictReader(open(root / "ground_truth.csv"))}
    assert m["symmetry_order"] == {n: int(r["symmetry_order"]) for n, r in truth.items()}
    gt = m["ground_truth"]
    assert gt["symmetry_detected"] == 1.0 and gt["modulo_symmetry"] and gt["within_one_view"] == 1.0
    assert gt["mean_error_deg"] <= 2.0 < gt["labels_mean_error_deg"]
    assert set(m["angles_deg"]) == set(m["labels"]) and all(0 <= a < 360 for a in m["angles_deg"].values())

    out = tables_project / "results" / "tables" / "export"
    rows = {r["shape"]: r for r in csv.DictReader(open(out / "alignment.csv"))}
    for n, a in m["angles_deg"].items():
        assert float(rows[n]["angle_deg"]) == pytest.approx(a, abs=0.006)
        assert int(rows[n]["symmetry_order"]) == m["symmetry_order"][n]

    # an exported chair is the input, normalized, turned back by its continuous angle
    from corr_core.alignment.azimuth import align_vertices_deg
    from corr_core.geometry.mesh_io import load_mesh, normalize_mesh
    chair = next(n for n, k in m["symmetry_order"].items() if k == 1)
    V, F = load_mesh(root / f"{chair}.obj")
    Vn, _, _ = normalize_mesh(V, center="area", F=F)
    Va, _ = load_mesh(out / "aligned_meshes" / f"{chair}.obj")
    np.testing.assert_allclose(Va, align_vertices_deg(Vn, m["angles_deg"][chair]), atol=1e-6)
