"""Targets (``run PIPELINE STAGE ...``, ``--until``) and ``--force STAGE`` (stages/select.py), in run, dry run and
sweep; a forced recompute replaces stored results whole."""
from __future__ import annotations

import json

import numpy as np
import pytest

from stages import api
from stages.cli import parse
from stages.errors import PipelineError
from stages.store import Store

from tests.helpers import cli_main, executed, make_project, run_quiet


@pytest.fixture()
def project(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return make_project(tmp_path, n=6)


def _created(plan, stage: str) -> list[float]:
    """The creation times of the stored entries of ``stage``."""
    return [plan.store.manifest(t.key)["created"] for t in plan.stages[stage].tasks]


def test_a_target_runs_only_what_it_needs(project, tmp_path):
    s = run_quiet(project, targets=["summary"])
    assert executed(s) == {"feat": 6, "dist": 3, "summary": 1}   # rep (after summary) is not planned
    assert not (tmp_path / "results" / "syn" / "rep").exists()
    assert not (tmp_path / "results" / "syn" / "metrics.json").exists()  # only a whole-pipeline run writes it
    rows = api.dry_run(api.plan_pipeline(str(project), quiet=True))
    assert [(r["stage"], r["reason"]) for r in rows] == [("rep", "new stage")]
    s = run_quiet(project, targets=["feat"], overrides=["sigma=2"])  # --until feat: nothing downstream runs
    assert executed(s) == {"feat": 0}
    # the run of feat only kept the record of summary: its reason still compares with the run that planned it
    rows = api.dry_run(api.plan_pipeline(str(project), ["sigma=2"], quiet=True))
    assert ("summary", "param sigma: 1.0 -> 2.0") in [(r["stage"], r["reason"]) for r in rows]


def test_dry_run_honours_targets_and_force(project, capsys):
    run_quiet(project)
    capsys.readouterr()
    api.run(str(project), workers=0, dry=True, targets=["dist"], force=["dist"])
    out = capsys.readouterr().out
    assert "summary" not in out and "rep" not in out
    assert "dist: 3 of 3 task(s) would run" in out and ": forced" in out
    assert "feat: 0 of 6 task(s) would run (all cached)" in out


def test_force_recomputes_the_stage_and_downstream_with_the_same_results(project):
    run_quiet(project)
    before = api.plan_pipeline(str(project), quiet=True)
    values = {t.key: before.store.get(t.key) for t in before.tasks()}
    created = {st: _created(before, st) for st in before.stages}
    s = run_quiet(project, force=["dist"])
    assert executed(s) == {"feat": 0, "dist": 3, "summary": 1, "rep": 1}
    after = api.plan_pipeline(str(project), quiet=True)
    assert [t.key for t in after.tasks()] == list(values)   # same keys, results replaced in place
    assert _created(after, "feat") == created["feat"]
    assert all(a > b for a, b in zip(_created(after, "dist"), created["dist"]))
    for k, v in values.items():
        got = after.store.get(k)
        if isinstance(v, np.ndarray):
            np.testing.assert_array_equal(got, v)
        else:
            assert got == v
    assert sum(executed(run_quiet(project)).values()) == 0   # forcing is for one run only


def test_force_and_targets_name_stages_of_the_pipeline(project):
    with pytest.raises(PipelineError, match="(?s)no stage 'sumary'.*did you mean 'summary'"):
        api.plan_pipeline(str(project), targets=["sumary"])
    with pytest.raises(PipelineError, match="--force rep: the targets of this run"):
        api.plan_pipeline(str(project), targets=["summary"], force=["rep"])
    res = cli_main(["run", "p.yaml", "--force", "nope", "--dry-run"], cwd=project.parent)
    assert res.returncode == 2 and "no stage 'nope'" in res.stderr and "Traceback" not in res.stderr


def test_targets_may_follow_options_and_until_is_the_same():
    args = parse(["run", "p.yaml", "--set", "a=1", "summary", "--until", "feat", "--force", "dist"])
    assert args.targets == ["summary", "feat"] and args.force == ["dist"] and args.sets == ["a=1"]
    assert parse(["sweep", "p.yaml", "--grid", "sigma=1,2", "--until", "summary"]).targets == ["summary"]
    with pytest.raises(SystemExit):
        parse(["status", "p.yaml", "summary"])   # status takes no targets


def test_sweep_takes_targets_and_force(project):
    api.sweep(str(project), ["sigma=1,2"], workers=0, quiet=True)
    plans = [api.plan_pipeline(str(project), [f"sigma={v}"], quiet=True) for v in (1, 2)]
    created = [(_created(p, "feat"), _created(p, "summary"), _created(p, "rep")) for p in plans]
    api.sweep(str(project), ["sigma=1,2"], workers=0, quiet=True, targets=["summary"], force=["summary"])
    for p, (feat, summary, rep) in zip(plans, created):
        assert _created(p, "feat") == feat and _created(p, "rep") == rep
        assert _created(p, "summary")[0] > summary[0]
    dry = api.sweep(str(project), ["sigma=1,2"], workers=0, quiet=True, dry=True, targets=["dist"])
    assert all("summary" not in row["report"] for row in dry["dry_run"])


def test_replacing_an_entry_never_leaves_the_old_manifest_over_new_data(tmp_path, monkeypatch):
    """A forced recompute that gives other content and is killed after its data moved into place, before its
    manifest: the entry is missing (recomputed next time), not the old manifest naming the new arrays."""
    import stages.store as store_module

    store = Store(str(tmp_path / "cache"))
    key = "0" * 32
    store.put(key, {"x": np.zeros(5)})

    def killed(path, text):
        raise OSError(28, "no space left on device", path)

    monkeypatch.setattr(store_module, "atomic_write_text", killed)
    with pytest.raises(OSError):
        store.put(key, {"x": np.ones(5)})
    monkeypatch.undo()
    assert not store.manifest_exists(key) and not store.has(key)
    store.put(key, {"x": np.ones(5)})
    np.testing.assert_array_equal(store.get(key)["x"], np.ones(5))
    # the same content again (two runs storing one key) keeps the manifest in place all along
    before = json.loads(open(store.manifest_path(key)).read())["created"]
    monkeypatch.setattr(store_module, "atomic_write_text", killed)
    with pytest.raises(OSError):
        store.put(key, {"x": np.ones(5)})
    monkeypatch.undo()
    assert store.has(key) and json.loads(open(store.manifest_path(key)).read())["created"] == before
    np.testing.assert_array_equal(store.get(key)["x"], np.ones(5))
