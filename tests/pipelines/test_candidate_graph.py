"""The alignment stages on a candidate graph (align.descriptor -> align.candidates -> align.pair_costs_sparse
with ``candidates:`` -> align.solve / align.evaluate on the sparse costs), against the dense complete graph:
generated chairs, every pair through the candidate path gives the dense answer, and the sparse graph aligns
every chair with a fraction of the pairs."""
from __future__ import annotations

import os

import pytest

from corr_core.alignment.azimuth import agreement_up_to_offset
from corr_core.generate import write_chair_collection
from stages import api

HEAD = """\
name: candidate_test
params: {graph: candidates, k: 3, n_random: 1}
datasets:
  shapes:
    groups: "chairs/*"
    pattern: '(?P<item>[^_/]+?)(?:_(?P<index>\\d+))?\\.(?:png|obj|off|ply)'
  ground_truth: {file: "chairs/ground_truth.csv"}
stages:
  views: {function: align.views, foreach: shapes, inputs: {files: shapes}, params: {image_size: 64}}
  hog: {function: align.hog, foreach: views, inputs: {views: views}}
"""
DENSE = HEAD + """\
  pairs: {function: align.pair_costs, pairs: hog, tile: 4}
  solve: {function: align.solve, inputs: {costs: pairs}, params: {solver: spectral}}
  evaluate:
    function: align.evaluate
    inputs: {costs: pairs, solution: solve, ground_truth: ground_truth}
    params: {seeds: [0], restarts: 1, compare_solvers: false}
    metrics: true
"""
GRAPH = HEAD + """\
  descriptor: {function: align.descriptor, foreach: hog, inputs: {features: hog}}
  candidates:
    function: align.candidates
    inputs: {descriptors: "descriptor[*]"}
    params: {graph: "${graph}", k: "${k}", n_random: "${n_random}"}
  pairs: {function: align.pair_costs_sparse, pairs: hog, candidates: candidates, tile: 4}
  solve: {function: align.solve, inputs: {costs: pairs, graph: candidates}, params: {solver: spectral}}
  evaluate:
    function: align.evaluate
    inputs: {costs: pairs, solution: solve, ground_truth: ground_truth, graph: candidates}
    params: {seeds: [0], restarts: 1, compare_solvers: false}
    metrics: true
"""
N = 16


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("candidates")
    write_chair_collection(tmp / "chairs", n=N, seed=5)
    (tmp / "dense.yaml").write_text(DENSE)
    (tmp / "graph.yaml").write_text(GRAPH)
    return tmp


def _run_and_metrics(tmp, client, file, sets=()):
    cwd = os.getcwd()
    os.chdir(tmp)
    try:
        summary = api.run(file, list(sets), client_getter=lambda: client, quiet=True)
        return summary, api.metrics(api.plan_pipeline(file, list(sets), quiet=True))
    finally:
        os.chdir(cwd)


def test_every_pair_through_the_candidate_path_gives_the_dense_answer(project, dask_client):
    _, dense = _run_and_metrics(project, dask_client, "dense.yaml")
    summary, complete = _run_and_metrics(project, dask_client, "graph.yaml", ["graph=complete"])
    assert summary["stages"]["views"]["executed"] == 0  # the views and HoG of the dense run are reused
    assert complete["pairs_computed"] == complete["pairs_total"] == N * (N - 1) // 2
    assert complete["labels"] == dense["labels"]
    assert complete["sigma"] == pytest.approx(dense["sigma"], rel=1e-5)
    assert "pairs_computed" not in dense  # the dense path's results are as before


def test_the_candidate_graph_aligns_every_chair_with_a_fraction_of_the_pairs(project, dask_client):
    _, dense = _run_and_metrics(project, dask_client, "dense.yaml")
    _, sparse = _run_and_metrics(project, dask_client, "graph.yaml")
    assert sparse["graph"] == "candidates"
    assert N - 1 <= sparse["pairs_computed"] <= N * 4 < sparse["pairs_total"]
    assert sparse["ground_truth"]["exact"] == 1.0 == dense["ground_truth"]["exact"]
    names = sorted(dense["labels"])
    assert agreement_up_to_offset([sparse["labels"][n] for n in names], [dense["labels"][n] for n in names],
                                  16)[0] == 1.0
