"""Sweeps and garbage collection: a sweep's points coexist in the cache; gc keeps what is reachable, and by default
removes only entries of the pipelines it is given."""
from __future__ import annotations

import pytest

from stages import api
from stages.cli import main

from tests.helpers import SYNTHETIC_YAML, executed, make_project, run_quiet


@pytest.fixture()
def project(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return make_project(tmp_path)


def test_sweep_resumes_and_gc_keeps_what_is_reachable(project, dask_client, tmp_path):
    res = api.sweep(str(project), ["sigma=0.5,1,2"], workers=0, quiet=True)
    assert [r["point"]["sigma"] for r in res["rows"]] == ["0.5", "1", "2"]
    values = [r["metrics"]["mean_affinity"] for r in res["rows"]]
    assert values[0] < values[1] < values[2]
    table = api.format_table(res["rows"])
    assert "mean_affinity" in table and len(table.splitlines()) == 5
    plans = [api.plan_pipeline(str(project), [f"sigma={s}"], quiet=True) for s in (0.5, 1, 2)]
    assert all(not p.missing() for p in plans)  # a second sweep would run nothing
    n_before = len(plans[0].store.all_keys())
    kept = api.gc([str(project)], dry=False, keep_sweeps=True)
    assert kept["removed"] == 0
    res = api.gc([str(project)], dry=False, keep_sweeps=False)
    assert res["removed"] == 2 * 2  # summary + rep of the two non-default sigmas
    assert len(plans[0].store.all_keys()) == n_before - 4


OTHER_YAML = SYNTHETIC_YAML.replace("name: syn", "name: other").replace("sigma: 1.0", "sigma: 5.0")


def _two_pipelines(tmp_path):
    """p.yaml and q.yaml share ./cache (and their feat and dist entries); each ran two configurations."""
    make_project(tmp_path, n=6)
    (tmp_path / "q.yaml").write_text(OTHER_YAML)
    for path, old in (("p.yaml", "sigma=2"), ("q.yaml", "sigma=7")):
        run_quiet(path, overrides=[old])
        run_quiet(path)
    return {name: {(st, t.key) for st, sp in api.plan_pipeline(f"{name}.yaml", [old], quiet=True).stages.items()
                   for t in sp.tasks if st in ("summary", "rep")}
            for name, old in (("p", "sigma=2"), ("q", "sigma=7"))}


def test_gc_keeps_to_its_pipeline_and_all_cleans_the_others(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    stale = _two_pipelines(tmp_path)
    res = api.gc(["p.yaml"], dry=True)
    assert {e["key"] for e in res["entries"]} == {k for _, k in stale["p"]}   # q's stale entries are not proposed
    assert all(e["pipelines"] == ["syn (p.yaml)"] for e in res["entries"]) and res["others_kept"] == 4  # q: 2 configs
    res = api.gc(["p.yaml"], dry=True, everything=True)   # everything p.yaml does not reach: q's current results too
    q_now = {t.key for st in ("summary", "rep") for t in api.plan_pipeline("q.yaml", quiet=True).stages[st].tasks}
    assert {e["key"] for e in res["entries"]} == {k for _, k in stale["p"] | stale["q"]} | q_now
    assert {tuple(e["pipelines"]) for e in res["entries"]} == {("syn (p.yaml)",), ("other (q.yaml)",)}
    # the dry run names the pipeline of each entry it would remove
    assert main(["gc", "p.yaml", "--dry-run", "--all"]) == 0
    out = capsys.readouterr().out
    assert "1 entry of stage summary" in out and "pipeline other (q.yaml)" in out and "pipeline syn (p.yaml)" in out
    store = api.plan_pipeline("p.yaml", quiet=True).store
    assert api.gc(["p.yaml"])["removed"] == 2
    assert all(store.has(k) for _, k in stale["q"]) and not any(store.has(k) for _, k in stale["p"])
    assert sum(executed(run_quiet("q.yaml", overrides=["sigma=7"])).values()) == 0   # q lost nothing
    assert api.gc(["p.yaml"], everything=True)["removed"] == 4
    assert not any(store.has(k) for _, k in stale["q"]) and not any(store.has(k) for k in q_now)
    assert sum(executed(run_quiet("p.yaml")).values()) == 0


def test_gc_leaves_entries_no_recorded_run_used_to_all(tmp_path, monkeypatch):
    """Entries of runs whose records are gone (or of a cache from before the ledgers) belong to no known
    pipeline: only --all removes them."""
    import shutil

    monkeypatch.chdir(tmp_path)
    make_project(tmp_path, n=6)
    run_quiet("p.yaml", overrides=["sigma=2"])
    shutil.rmtree(tmp_path / "cache" / "runs")
    run_quiet("p.yaml")
    assert api.gc(["p.yaml"], dry=True)["removed"] == 0
    res = api.gc(["p.yaml"], dry=True, everything=True)
    assert res["removed"] == 2 and {tuple(e["pipelines"]) for e in res["entries"]} == {("no recorded pipeline",)}
