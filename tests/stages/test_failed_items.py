"""One bad item does not sink the collection, and optional inputs skip cleanly.

A collection stage whose items partly failed runs on the others and records which it left out and why; pair
stages tile only the items that succeeded; the exit code is 1. A group with missing parts (a missing view) is
an item failure. An absent or empty optional dataset skips the stages that need it, with why, while everything
else completes. File names that do not match a dataset's pattern are named in a warning.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from stages import api
from stages.plan import plan_pipeline

from tests.helpers import COURSE_DATA, ROOT, cli, executed, make_project

BROKEN = "s013"


@pytest.fixture()
def project27(tmp_path, monkeypatch):
    """27 synthetic items; item s013 carries the marker that makes synthetic.features fail."""
    monkeypatch.chdir(tmp_path)
    p = make_project(tmp_path, n=27)
    (tmp_path / "data" / f"{BROKEN}.txt").write_text("item 13 BROKEN\n")
    return p


def _run(path, **kw):
    try:
        return api.run(str(path), workers=0, quiet=True, **kw), 0
    except api.RunFailed as exc:
        return exc.summary, 1


def test_a_collection_runs_on_the_items_that_succeeded(project27, tmp_path):
    sets = ["feat.fail_on=BROKEN"]
    summary, rc = _run(project27, overrides=sets)
    assert rc == 1
    assert [(f["stage"], f["item"]) for f in summary["failures"]] == [("feat", BROKEN)]
    assert executed(summary)["summary"] == 1 and executed(summary)["rep"] == 1  # not skipped
    m = api.metrics(plan_pipeline(str(project27), sets))
    assert m["n_items"] == 26 and BROKEN not in m["names"]          # the pair matrix holds only the 26
    assert m["_left_out"]["summary"] == [{"item": f"feat[{BROKEN}]",
                                          "why": m["_left_out"]["summary"][0]["why"]}]
    assert "BROKEN" in m["_left_out"]["summary"][0]["why"]
    metrics_file = json.loads((tmp_path / "results" / "syn" / "metrics.json").read_text())
    assert metrics_file["_left_out"] == m["_left_out"]
    assert (tmp_path / "results" / "syn" / "rep" / "summary.txt").read_text().startswith("synthetic: 26 items")
    html = Path(api.write_report(str(project27), sets)).read_text(encoding="utf-8")
    assert f"summary left out 1 failed item(s): feat[{BROKEN}]" in html


def test_a_rerun_retries_the_failed_item_only(project27):
    sets = ["feat.fail_on=BROKEN"]
    _run(project27, overrides=sets)
    summary, rc = _run(project27, overrides=sets)
    assert rc == 1
    assert sum(executed(summary).values()) == 0           # it failed again; everything else is cached
    assert summary["stages"]["feat"]["failed"] == 1


def test_fixing_the_item_completes_the_collection(project27, tmp_path):
    sets = ["feat.fail_on=BROKEN"]
    _run(project27, overrides=sets)
    (tmp_path / "data" / f"{BROKEN}.txt").write_text("item 13 repaired\n")
    summary, rc = _run(project27, overrides=sets)
    assert rc == 0
    m = api.metrics(plan_pipeline(str(project27), sets))
    assert m["n_items"] == 27 and "_left_out" not in m


def test_the_partial_result_equals_a_run_without_the_item(project27, tmp_path):
    sets = ["feat.fail_on=BROKEN"]
    _run(project27, overrides=sets)
    partial = api.metrics(plan_pipeline(str(project27), sets))
    (tmp_path / "data" / f"{BROKEN}.txt").unlink()
    _run(project27, overrides=sets)
    without = api.metrics(plan_pipeline(str(project27), sets))
    assert partial["mean_affinity"] == without["mean_affinity"]
    assert partial["names"] == without["names"]


def test_a_group_with_a_missing_part_is_an_item_failure(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "v").mkdir()
    for item in ("a", "b", "c"):
        for i in range(3):
            if (item, i) != ("b", 1):
                (tmp_path / "v" / f"{item}_{i}.png").write_bytes(b"x")
    p = tmp_path / "g.yaml"
    p.write_text("datasets: {shapes: {groups: 'v/*', pattern: '(?P<item>[a-z]+)_(?P<index>\\d+)\\.png'}}\n"
                 "stages: {c: {function: synthetic.collect, inputs: {items: shapes}}}\n")
    plan = plan_pipeline(str(p))                      # no pipeline error
    assert "missing parts [1]" in plan.datasets["shapes"].items["b"].error
    assert plan.datasets["shapes"].items["a"].error == ""


def test_an_empty_optional_dataset_skips_the_stages_that_need_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    make_project(tmp_path, n=5)
    p = tmp_path / "o.yaml"
    p.write_text("params: {extra_root: ''}\n"
                 "datasets:\n  items: {files: 'data/*.txt'}\n"
                 "  extra: {files: '${extra_root}/*.txt', optional: true}\n"
                 "stages:\n"
                 "  feat: {function: synthetic.features, foreach: items, inputs: {path: items}}\n"
                 "  extra_feat: {function: synthetic.features, foreach: extra, inputs: {path: extra}}\n"
                 "  extra_all: {function: synthetic.collect, inputs: {items: 'extra_feat[*]'}}\n"
                 "  all: {function: synthetic.collect, inputs: {items: 'feat[*]'}, metrics: true}\n")
    for root in ("", "nowhere", "empty_folder"):
        (tmp_path / "empty_folder").mkdir(exist_ok=True)
        plan = plan_pipeline(str(p), [f"extra_root={root}"])
        assert plan.stages["extra_feat"].skipped and plan.stages["extra_all"].skipped
        assert "optional dataset 'extra'" in plan.stages["extra_all"].skipped
        summary, rc = _run(p, overrides=[f"extra_root={root}"])
        assert rc == 0 and summary["stages"]["extra_all"]["skipped_stage"]
        assert executed(summary)["all"] in (0, 1)
    rows = {r["stage"]: r for r in api.status(str(p))}
    assert rows["extra_feat"]["skipped"] and rows["all"]["skipped"] is None


def test_an_optional_input_of_a_skipped_stage_is_passed_as_none(tmp_path, monkeypatch):
    """align.evaluate(other=None): with no compare folder the comparison is left out, evaluate still runs."""
    monkeypatch.chdir(tmp_path)
    plan = plan_pipeline(str(ROOT / "pipelines" / "chairs.yaml"),
                         [f"data.root={_tiny_meshes(tmp_path / 'mine')}", "data.compare_root="],
                         cache_dir=str(tmp_path / "c"))
    assert plan.stages["compare_solve"].skipped
    assert plan.stages["evaluate"].skipped is None and len(plan.stages["evaluate"].tasks) == 1
    assert plan.stages["evaluate"].tasks[0].inputs["other"].value is None


def _tiny_meshes(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    tet = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
    for name in ("001.obj", "002.obj", "UPPER.OBJ", "my_chair.obj", "notes.txt"):
        (folder / name).write_text(tet)
    return folder


def test_file_names_that_do_not_match_the_pattern_are_named(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    plan = plan_pipeline(str(ROOT / "pipelines" / "chairs.yaml"),
                         [f"data.root={_tiny_meshes(tmp_path / 'mine')}", "data.compare_root="],
                         cache_dir=str(tmp_path / "c"))
    assert sorted(plan.datasets["shapes"].items) == ["001", "002", "UPPER"]  # upper-case extension accepted
    err = capsys.readouterr().err
    assert "my_chair.obj" in err and "notes.txt" not in err


def test_files_datasets_accept_upper_case_extensions(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    make_project(tmp_path, n=3)
    (tmp_path / "data" / "LOUD.TXT").write_text("item loud\n")
    plan = plan_pipeline(str(tmp_path / "p.yaml"))
    assert "LOUD" in plan.datasets["items"].items


@pytest.mark.course
@pytest.mark.e2e
def test_chairs_on_own_views_with_a_missing_view_and_no_compare_folder(tmp_path):
    """27 course chairs (pre-rendered views) in a folder of one's own, one view of one chair deleted, no
    compare folder: views of that chair fails, everything else (pairs, solve, evaluate, labels) completes."""
    src = COURSE_DATA / "chairs_rendering"
    names = sorted({p.name.split("_")[0] for p in src.glob("*_0.png")})[:27]
    mine = tmp_path / "mine"
    mine.mkdir()
    for n in names:
        for f in src.glob(f"{n}_*.png"):
            shutil.copyfile(f, mine / f.name)
    broken = names[3]
    (mine / f"{broken}_5.png").unlink()
    args = ["pipelines/chairs.yaml", "--set", f"data.root={mine}", "--set", "data.compare_root=",
            "--cache", str(tmp_path / "c")]
    r = cli(["run", *args, "--out", str(tmp_path / "o"), "--workers", "2"], ROOT, timeout=900)
    assert r.returncode == 1, r.stderr
    assert f"FAILED views[{broken}]" in r.stderr and "missing parts [5]" in r.stderr
    assert "Traceback" not in r.stderr and "AxisError" not in r.stderr
    assert "skipped: optional dataset 'compare_shapes'" in r.stdout
    r = cli(["results", *args, "--json"], ROOT)
    assert r.returncode == 0, r.stderr
    m = json.loads(r.stdout)
    assert len(m["labels"]) == 26 and broken not in m["labels"]
    assert m["_left_out"]["evaluate"][0]["item"] == f"views[{broken}]"
    assert "mode_agreement" not in m or not m["mode_agreement"]
    assert "compare_solve" in m["_skipped"] if "_skipped" in m else True
