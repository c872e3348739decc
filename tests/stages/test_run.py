"""Incremental reruns at item granularity, counted by executed tasks on a real LocalCluster."""
from __future__ import annotations

import os
import warnings

import numpy as np
import pytest

from stages import api
from stages.checksums import digest_json

from tests.helpers import executed, make_project


@pytest.fixture()
def project(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return make_project(tmp_path)


def _run(path, dask_client, **kw):
    return api.run(str(path), client_getter=lambda: dask_client, quiet=True, **kw)


def test_cold_then_noop_runs_nothing(project, dask_client):
    s1 = _run(project, dask_client)
    n_tiles = len(api.plan_pipeline(str(project), quiet=True).stages["dist"].tasks)
    assert executed(s1) == {"feat": 12, "dist": n_tiles, "summary": 1, "rep": 1}
    s2 = _run(project, dask_client)
    assert executed(s2) == {"feat": 0, "dist": 0, "summary": 0, "rep": 0}
    assert s2["stages"]["feat"]["cached"] == 12


def test_param_change_reruns_only_downstream(project, dask_client):
    _run(project, dask_client)
    s = _run(project, dask_client, overrides=["sigma=2.5"])
    assert executed(s) == {"feat": 0, "dist": 0, "summary": 1, "rep": 1}
    # both configurations coexist: going back costs nothing
    s = _run(project, dask_client, overrides=["sigma=1.0"])
    assert sum(executed(s).values()) == 0
    # a stage-level override works the same way
    s = _run(project, dask_client, overrides=["summary.sigma=3"])
    assert executed(s) == {"feat": 0, "dist": 0, "summary": 1, "rep": 1}


def test_editing_one_item_reruns_its_tasks_and_tiles(project, dask_client, tmp_path):
    _run(project, dask_client)
    plan = api.plan_pipeline(str(project), quiet=True)
    names = plan.stages["dist"].source.pairs.names
    blocks = plan.stages["dist"].source.pairs.blocks
    edited = "s005"
    block_of = next(i for i, (a, b) in enumerate(blocks) if a <= names.index(edited) < b)
    tiles_with_it = sum(1 for bi, bj, _ in plan.stages["dist"].source.pairs.tiles if block_of in (bi, bj))
    (tmp_path / "data" / f"{edited}.txt").write_text("edited content\n")
    rows = api.dry_run(api.plan_pipeline(str(project), quiet=True))
    assert {r["label"] for r in rows if r["stage"] == "feat"} == {edited}
    assert any("changed" in r["reason"] for r in rows if r["stage"] == "dist")
    s = _run(project, dask_client)
    assert executed(s) == {"feat": 1, "dist": tiles_with_it, "summary": 1, "rep": 1}
    assert tiles_with_it < len(plan.stages["dist"].tasks)


def test_adding_one_item_reruns_only_tiles_that_contain_it(project, dask_client, tmp_path):
    _run(project, dask_client)
    before = api.plan_pipeline(str(project), quiet=True)
    old_keys = {t.key for t in before.stages["dist"].tasks}
    # an item name that does not start a new block (see make_blocks); 1 in `tile` names would split a block
    new = next(n for n in (f"s{i:03d}b" for i in range(100)) if int(digest_json(n)[:8], 16) % 4 != 0)
    (tmp_path / "data" / f"{new}.txt").write_text("a new shape\n")
    after = api.plan_pipeline(str(project), quiet=True)
    pairs = after.stages["dist"].source.pairs
    idx = pairs.names.index(new)
    new_block = next(i for i, (a, b) in enumerate(pairs.blocks) if a <= idx < b)
    expected = [t for t in pairs.tiles if new_block in (t[0], t[1])]
    rows = api.dry_run(after)
    assert [r["reason"] for r in rows if r["stage"] == "feat"] == ["new item"]
    s = _run(project, dask_client)
    assert executed(s) == {"feat": 1, "dist": len(expected), "summary": 1, "rep": 1}
    assert {t[2] for t in pairs.tiles} - old_keys == {t[2] for t in expected}



def test_results_match_a_plain_loop(project, dask_client, tmp_path):
    _run(project, dask_client)
    plan = api.plan_pipeline(str(project), quiet=True)
    value = plan.store.get(plan.stages["summary"].tasks[0].key)
    from tests.stages import synthetic_plugin as synthetic
    files = sorted((tmp_path / "data").glob("*.txt"))
    F = {f.stem: synthetic.features(str(f)) for f in files}
    names = sorted(F)
    M = synthetic.pair_distances(np.stack([F[n] for n in names]), np.stack([F[n] for n in names]))
    ref = synthetic.summarize({"names": names, "matrix": M}, sigma=1.0)
    assert value["names"] == names
    assert value["mean_affinity"] == pytest.approx(ref["mean_affinity"], rel=1e-3)
    assert value["mean_affinity"] < 0.9  # distinct features: not a degenerate all-ones matrix


def test_failing_item_is_reported_and_others_finish(project, dask_client, tmp_path):
    (tmp_path / "data" / "s003.txt").write_text("BROKEN marker\n")
    with pytest.raises(api.RunFailed) as info:
        _run(project, dask_client, overrides=["feat.fail_on=BROKEN"])
    summary = info.value.summary
    assert [(f["stage"], f["item"]) for f in summary["failures"]] == [("feat", "s003")]
    assert "s003" in summary["failures"][0]["error"] and "BROKEN" in summary["failures"][0]["error"]
    assert summary["stages"]["feat"]["executed"] == 11
    # the collection stages run on the 11 items that succeeded (tests/stages/test_failed_items.py)
    assert summary["stages"]["summary"]["executed"] == 1 and not summary["skipped"]
    (tmp_path / "data" / "s003.txt").write_text("fixed\n")
    s = _run(project, dask_client, overrides=["feat.fail_on=BROKEN"])
    assert s["stages"]["feat"]["executed"] == 1 and s["stages"]["summary"]["executed"] == 1


def test_corrupted_chunk_is_detected_and_recomputed(project, dask_client):
    _run(project, dask_client)
    plan = api.plan_pipeline(str(project), quiet=True)
    tile_key = plan.stages["dist"].tasks[0].key
    before = plan.store.get(tile_key)
    chunk_files = [os.path.join(d, f) for d, _, fs in os.walk(plan.store.object_path(tile_key))
                   for f in fs if "zarr.json" not in f]
    assert chunk_files
    with open(chunk_files[0], "r+b") as fh:  # flip bytes inside the compressed chunk
        data = bytearray(fh.read())
        for i in range(len(data) // 2, min(len(data), len(data) // 2 + 8)):
            data[i] ^= 0xFF
        fh.seek(0)
        fh.write(bytes(data))
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        s = _run(project, dask_client, overrides=["sigma=4"])
    assert s["stages"]["dist"]["executed"] == 1 and s["stages"]["summary"]["executed"] == 1
    np.testing.assert_array_equal(plan.store.get(tile_key), before)


def test_engine_writes_only_under_cache_and_output(project, dask_client, tmp_path):
    _run(project, dask_client)
    assert sorted(os.listdir(tmp_path)) == ["cache", "data", "p.yaml", "results"]
    assert (tmp_path / "results" / "syn" / "rep" / "summary.txt").is_file()
    assert (tmp_path / "results" / "syn" / "metrics.json").is_file()


def test_run_says_why_each_stage_runs(project, tmp_path, capsys):
    """One line per stage that executes anything: its number of tasks and the first reason."""
    api.run(str(project), workers=0)
    assert "  feat: 12 tasks (no earlier run of this pipeline)" in capsys.readouterr().err
    api.run(str(project), workers=0, overrides=["sigma=2"])
    err = capsys.readouterr().err
    assert "  summary: 1 task (param sigma: 1.0 -> 2.0)" in err
    assert "  rep: 1 task (input summary (summary) changed)" in err
    assert "feat:" not in err.replace("feat: 0", "")   # a stage that executes nothing gets no line
    (tmp_path / "data" / "s003.txt").write_text("edited\n")
    (tmp_path / "data" / "s100.txt").write_text("new\n")
    api.run(str(project), workers=0, overrides=["sigma=2"])
    err = capsys.readouterr().err
    assert "  feat: 2 tasks (input path (items[s003]) changed; and 1 other reason: see --dry-run)" in err


def test_quiet_run_keeps_failures_and_drops_reasons(project, tmp_path, capsys):
    (tmp_path / "data" / "s003.txt").write_text("BROKEN marker\n")
    with pytest.raises(api.RunFailed):
        api.run(str(project), workers=0, quiet=True, overrides=["feat.fail_on=BROKEN"])
    err = capsys.readouterr().err
    assert "FAILED feat[s003]" in err and "tasks (" not in err and "running" not in err
