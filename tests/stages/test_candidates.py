"""Pair stages on a candidate graph (``candidates: STAGE``): costs only for the pairs a once stage names.

The pair stage waits (no tasks, honest dry runs) until the candidates stage's result is in the cache; ``run``
then plans again and computes one task per block of first items, each loading only its own items. The
consumer gets ``{"names", "pairs", "values"}``, never an N x N matrix. Bad candidates, and a pair function that
cannot take ``pairs``, are clear errors naming the stage.
"""
from __future__ import annotations

import re

import json
from pathlib import Path

import numpy as np
import pytest

from stages import api
from stages.candidates import candidate_pairs
from stages.config import load_pipeline
from stages.errors import PipelineError, UserError
from stages.execute import execute
from stages.plan import build_plan, plan_pipeline

from tests.helpers import cli, cli_main, executed, loaded_plugin, make_project
from tests.stages import synthetic_plugin as synthetic
from tests.stages.test_pure_planning import listing

CANDIDATE_YAML = """\
name: cand
params: {k: 2}
datasets:
  items: {files: "data/*.txt"}
stages:
  feat: {function: synthetic.features, foreach: items, inputs: {path: items}}
  cand: {function: synthetic.candidates, inputs: {items: "feat[*]"}, params: {k: "${k}"}}
  dist: {function: synthetic.pair_distances_at, pairs: feat, candidates: cand, tile: 4}
  out: {function: synthetic.collect_pairs, inputs: {distances: dist}}
"""
COMPLETE_YAML = CANDIDATE_YAML.replace(", candidates: cand", "").replace(
    "  out: {function: synthetic.collect_pairs, inputs: {distances: dist}}\n", "")


def _run(path, **kw):
    try:
        return api.run(str(path), workers=kw.pop("workers", 0), quiet=True, **kw), 0
    except api.RunFailed as exc:
        return exc.summary, 1


def _out(path, overrides=()) -> dict:
    """The consumer's stored value: what the stage after the candidate pair stage received."""
    plan = plan_pipeline(str(path), list(overrides))
    return plan.store.get(plan.stages["out"].tasks[0].key)


def _expected(data: Path, names: list[str], pairs: np.ndarray) -> np.ndarray:
    """(P,) float32 squared feature distances computed directly from the item files (no engine)."""
    F = {n: synthetic.features(str(data / f"{n}.txt")).astype(np.float64).ravel() for n in names}
    return np.array([((F[names[i]] - F[names[j]]) ** 2).sum() for i, j in pairs], dtype=np.float32)


@pytest.fixture()
def project(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return make_project(tmp_path, n=14, yaml_text=CANDIDATE_YAML)


def test_values_are_those_of_the_complete_graph_on_the_candidate_pairs(project, tmp_path):
    summary, rc = _run(project)
    assert rc == 0
    got = _out(project)
    names = [f"s{i:03d}" for i in range(14)]
    ring = {tuple(sorted((i, (i + s) % 14))) for i in range(14) for s in (1, 2)}
    assert got["names"] == names and got["n_pairs"] == len(ring) == 28
    assert got["pairs"].dtype == np.int64 and [tuple(p) for p in got["pairs"]] == sorted(ring)  # i < j, sorted
    assert got["values"].shape == (28,)
    np.testing.assert_array_equal(got["values"], _expected(tmp_path / "data", names, got["pairs"]))
    complete = tmp_path / "complete.yaml"
    complete.write_text(COMPLETE_YAML)
    _run(complete)
    plan = plan_pipeline(str(complete))
    full = plan.stages["dist"].source.pairs.load(plan.store)
    assert full["names"] == names
    i, j = got["pairs"].T
    np.testing.assert_array_equal(got["values"], full["matrix"][i, j])
    assert executed(summary)["dist"] == len(plan_pipeline(str(project)).stages["dist"].tasks) < \
        len(plan.stages["dist"].tasks)                               # fewer tasks than the complete graph's tiles


def test_each_task_loads_only_its_own_items(project):
    _run(project)
    plan = plan_pipeline(str(project))
    feat_keys = {plan.stages["feat"].source.items[n].entry: n for n in plan.stages["feat"].source.items}
    pairs = plan.stages["dist"].source.pairs
    covered = []
    for (start, end, key), task in zip(pairs.tasks, plan.stages["dist"].tasks):
        assert task.key == key
        A = [feat_keys[p.entry] for p in task.inputs["A"].parts]
        B = [feat_keys[p.entry] for p in task.inputs["B"].parts]
        local = task.inputs["pairs"].pairs
        glob_pairs = [(A[a], B[b]) for a, b in local]
        assert glob_pairs == [(pairs.names[i], pairs.names[j]) for i, j in pairs.pairs[start:end]]
        assert set(A) == {a for a, _ in glob_pairs} and set(B) == {b for _, b in glob_pairs}  # nothing unused
        covered.append((start, end))
    assert covered[0][0] == 0 and covered[-1][1] == len(pairs.pairs)
    assert all(e == s for (_, e), (s, _) in zip(covered, covered[1:]))


def test_dry_run_waits_for_the_candidates_then_lists_the_tasks(project, tmp_path):
    before = listing(tmp_path)
    dry = cli_main(["run", "p.yaml", "--dry-run"], cwd=tmp_path)
    assert dry.returncode == 0, dry.stderr
    assert "dist: would run once stage 'cand' has run (its tasks are the candidate pairs" in dry.stdout
    assert "out: would run once stage 'cand' has run" in dry.stdout
    assert "2 stage(s) planned once cand has run" in dry.stdout
    status = json.loads(cli_main(["status", "p.yaml", "--json"], cwd=tmp_path).stdout)
    rows = {r["stage"]: r for r in status}
    assert rows["dist"]["to_run"] is None and rows["dist"]["waiting_for"] == "cand" and rows["dist"]["tasks"] == 0
    assert rows["cand"]["to_run"] == 1 and "waiting_for" not in rows["cand"]
    assert listing(tmp_path) == before                                        # planning wrote nothing
    plan = plan_pipeline(str(project))
    execute(plan.missing(), plan.store)                                       # round 1 only: feat and cand
    after = cli_main(["run", "p.yaml", "--dry-run"], cwd=tmp_path)
    n_tasks = len(plan_pipeline(str(project)).stages["dist"].tasks)
    assert n_tasks > 1 and f"dist: {n_tasks} of {n_tasks} task(s) would run" in after.stdout, after.stdout
    assert "out: 1 of 1 task(s) would run" in after.stdout and "planned once" not in after.stdout


def test_changing_one_item_reruns_only_the_tasks_with_its_pairs(project, tmp_path):
    _run(project)
    (tmp_path / "data" / "s005.txt").write_text("changed content\n")
    assert plan_pipeline(str(project)).stages["dist"].waiting == "cand"     # cand's input changed: it reruns first
    summary, rc = _run(project)
    assert rc == 0
    plan = plan_pipeline(str(project))
    new_key = plan.stages["feat"].source.items["s005"].entry
    touching = [t for t in plan.stages["dist"].tasks
                if new_key in {p.entry for arg in ("A", "B") for p in t.inputs[arg].parts}]
    assert 0 < len(touching) < len(plan.stages["dist"].tasks)
    assert executed(summary) == {"feat": 1, "cand": 1, "dist": len(touching), "out": 1}
    names = [f"s{i:03d}" for i in range(14)]
    got = _out(project)
    np.testing.assert_array_equal(got["values"], _expected(tmp_path / "data", names, got["pairs"]))


def test_adding_an_item_reruns_only_the_tasks_whose_pairs_changed(project, tmp_path):
    _run(project, overrides=["k=1"])
    old = {t.label: t.key for t in plan_pipeline(str(project), ["k=1"]).stages["dist"].tasks}
    (tmp_path / "data" / "s007b.txt").write_text("a new item\n")              # between s007 and s008
    summary, rc = _run(project, overrides=["k=1"])
    new = plan_pipeline(str(project), ["k=1"]).stages["dist"].tasks
    assert rc == 0 and executed(summary)["dist"] == sum(old.get(t.label) != t.key for t in new)
    assert 0 < executed(summary)["dist"] <= 2 < len(new)


@pytest.mark.parametrize("stage, fix", [
    ("{function: synthetic.pair_distances, pairs: feat, candidates: cand}", "it has no argument 'pairs'"),
    ("{function: synthetic.pair_distances_at, pairs: feat, candidates: items}", "'items' is a dataset"),
    ("{function: synthetic.pair_distances_at, pairs: feat, candidates: feat}", "the candidates stage must run once"),
    ("{function: synthetic.pair_distances_at, pairs: feat, candidates: nope}", "unknown stage 'nope'"),
    ("{function: synthetic.collect, inputs: {items: feat}, candidates: cand}", "only for pair stages"),
])
def test_a_stage_that_cannot_run_on_candidates_is_a_clear_error(tmp_path, stage, fix):
    p = make_project(tmp_path, n=3, yaml_text=CANDIDATE_YAML.replace(
        "{function: synthetic.pair_distances_at, pairs: feat, candidates: cand, tile: 4}", stage).replace(
        "  out: {function: synthetic.collect_pairs, inputs: {distances: dist}}\n", ""))
    with pytest.raises(PipelineError) as e:
        load_pipeline(str(p))
    assert e.value.key.startswith("stages.dist") and fix in e.value.message and e.value.fix, e.value


@pytest.mark.parametrize("bad, problem", [
    ("self", "pair 1 is (2, 2): an item paired with itself"),
    ("range", "pair 0 is (0, 14): an index outside 0..13"),
    ("shape", "'pairs' has shape (28, 3), expected (P, 2)"),
    ("names", "'names' has 1 name(s) that are not items of 'feat': 'no_such_item'"),
    ("float", "'pairs' must hold integer indices into 'names', got dtype float64"),
])
def test_bad_candidates_are_an_error_naming_the_stage(project, tmp_path, bad, problem):
    sets = [f"cand.bad={bad}"]
    with pytest.raises(PipelineError) as e:
        _run(project, overrides=sets)
    text = str(e.value)
    assert "stage 'cand' (synthetic.candidates) returned unusable candidate pairs for the pair stage 'dist'" in text
    assert problem in text and "fix: make synthetic.candidates return {'names'" in text, text
    if bad == "self":  # the command line: one error with its fix, no traceback, exit 2 (also for status)
        for args in (["run", "p.yaml", "--set", "cand.bad=self"], ["status", "p.yaml", "--set", "cand.bad=self"]):
            res = cli(args, cwd=tmp_path)
            assert res.returncode == 2 and problem in res.stderr and "Traceback" not in res.stderr, res.stderr


def test_a_function_that_needs_pairs_needs_candidates(tmp_path, monkeypatch):
    source = ("from stages.registry import register\n"
              "@register('tmp_needs.pairs', fanout='pair')\n"
              "def needs(A, B, *, pairs):\n    return A[pairs[:, 0]]\n")
    with loaded_plugin(tmp_path, monkeypatch, "tmp_needs_pairs", source):
        p = make_project(tmp_path, n=3, yaml_text=COMPLETE_YAML.replace("synthetic.pair_distances_at", "tmp_needs.pairs"))
        with pytest.raises(PipelineError) as e:
            load_pipeline(str(p))
    assert e.value.key == "stages.dist" and "needs candidate pairs" in e.value.message and "candidates:" in e.value.fix


def test_candidate_pairs_are_made_canonical():
    items = ["a", "b", "c", "d"]
    got = candidate_pairs({"names": ["d", "b", "a"], "pairs": np.array([[0, 1], [1, 0], [2, 0], [1, 2]]),
                           "extra": 1}, items, "feat")
    assert got.dtype == np.int64 and got.tolist() == [[0, 1], [0, 3], [1, 3]]   # (b,d)=(d,b), (a,d), (a,b)
    assert candidate_pairs({"names": items, "pairs": np.zeros((0, 2), int)}, items, "feat").shape == (0, 2)
    with pytest.raises(ValueError, match="not a dict with the keys 'names' and 'pairs'"):
        candidate_pairs({"pairs": []}, items, "feat")
    with pytest.raises(ValueError, match="'names' lists 'a' more than once"):
        candidate_pairs({"names": ["a", "a"], "pairs": np.zeros((0, 2), int)}, items, "feat")


def test_a_failed_item_is_left_out_with_its_pairs(tmp_path, monkeypatch):
    """Candidates over the dataset itself: the pair tasks holding the item whose feature failed run on the
    others; the consumer's names and pairs leave it out and say so."""
    monkeypatch.chdir(tmp_path)
    p = make_project(tmp_path, n=14, yaml_text=CANDIDATE_YAML.replace('{items: "feat[*]"}', '{items: "items[*]"}'))
    (tmp_path / "data" / "s006.txt").write_text("BROKEN\n")
    sets = ["feat.fail_on=BROKEN"]
    summary, rc = _run(p, overrides=sets)
    assert rc == 1 and [(f["stage"], f["item"]) for f in summary["failures"]] == [("feat", "s006")]
    got = _out(p, sets)
    names = [f"s{i:03d}" for i in range(14) if i != 6]
    assert got["names"] == names and got["pairs"].max() == 12
    ring = {tuple(sorted((i, (i + s) % 14))) for i in range(14) for s in (1, 2)}
    kept = sorted((i - (i > 6), j - (j > 6)) for i, j in ring if 6 not in (i, j))
    assert [tuple(q) for q in got["pairs"]] == kept
    np.testing.assert_array_equal(got["values"], _expected(tmp_path / "data", names, got["pairs"]))
    plan = plan_pipeline(str(p), sets)
    assert [e[2] for e in plan.store.left_out(plan.stages["out"].tasks[0].key)] == ["s006"]


def test_a_candidates_stage_without_an_item_leaves_it_out_downstream(project, tmp_path):
    """Candidates over ``feat[*]``: the item whose feature failed is in no pair; the consumer leaves it out too."""
    (tmp_path / "data" / "s006.txt").write_text("BROKEN\n")
    sets = ["feat.fail_on=BROKEN"]
    assert _run(project, overrides=sets)[1] == 1
    got = _out(project, sets)
    assert "s006" not in got["names"] and len(got["names"]) == 13 and got["pairs"].max() == 12
    plan = plan_pipeline(str(project), sets)
    assert [e[2] for e in plan.store.left_out(plan.stages["out"].tasks[0].key)] == ["s006"]


def test_same_results_on_one_and_two_workers(tmp_path, dask_client):
    outs, keys = [], []
    for name, kw in (("one", {"workers": 1}), ("two", {"client_getter": lambda: dask_client, "workers": 2})):
        folder = tmp_path / name
        p = make_project(folder, n=14, yaml_text=CANDIDATE_YAML.replace("data/", f"{folder}/data/"))
        summary, rc = _run(p, cache_dir=str(folder / "cache"), output_dir=str(folder / "out"), **kw)
        assert rc == 0 and executed(summary)["dist"] > 1
        plan = build_plan(load_pipeline(str(p), cache_dir=str(folder / "cache")))
        outs.append(plan.store.get(plan.stages["out"].tasks[0].key))
        keys.append([t.key for t in plan.stages["dist"].tasks])
    assert keys[0] == keys[1]
    assert outs[0]["names"] == outs[1]["names"]
    for k in ("pairs", "values"):
        assert outs[0][k].dtype == outs[1][k].dtype
        np.testing.assert_array_equal(outs[0][k], outs[1][k])


def test_a_damaged_candidates_result_is_recomputed(project, capsys):
    _run(project)
    plan = plan_pipeline(str(project))
    key = plan.stages["cand"].tasks[0].key
    chunks = [p for p in Path(plan.store.object_path(key)).rglob("*") if p.is_file() and p.name != "zarr.json"]
    chunk = max(chunks, key=lambda p: p.stat().st_size)
    data = bytearray(chunk.read_bytes())
    data[-1] ^= 0xFF                                                   # same size, other content
    chunk.write_bytes(bytes(data))
    assert plan.store.has(key)
    capsys.readouterr()
    rows = {r["stage"]: r for r in api.status(str(project))}
    assert rows["dist"]["waiting_for"] == "cand" and "damaged" in rows["dist"]["reasons"][0]
    summary, rc = _run(project)
    assert len(re.findall(r"warning: cache entry \w+ is corrupt.*recomputing it", capsys.readouterr().err)) == 1
    assert rc == 0 and executed(summary)["cand"] == 1 and executed(summary)["dist"] == 0   # tasks were cached
    assert _out(project)["n_pairs"] == 28


def test_gc_removes_nothing_while_a_pair_stage_waits_for_its_candidates(project, tmp_path):
    _run(project)
    plan = plan_pipeline(str(project))
    pair_keys = [t.key for t in plan.stages["dist"].tasks]
    (tmp_path / "data" / "s005.txt").write_text("changed content\n")   # cand must rerun: dist's tasks unknown
    with pytest.raises(UserError, match="wait for candidates stage"):
        api.gc([str(project)], dry=False)
    assert all(plan.store.has(k) for k in pair_keys)                   # the reusable pair entries are still there
    assert api.gc([str(project)], dry=True)["dry_run"]                  # a dry run still reports
