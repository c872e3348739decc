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


# --- a folder is adopted as a cache only when it holds exactly what the engine writes ---

import os  # noqa: E402
import shutil  # noqa: E402
import time  # noqa: E402
import uuid  # noqa: E402

from stages.errors import UserError  # noqa: E402
from stages.cache_root import CACHE_MARKER  # noqa: E402

from tests.helpers import run_quiet  # noqa: E402

_HEX = "0123456789abcdef" * 2
_USER_FILES = ["manifesto.txt", "runs_2023.csv", "objects_old/a.txt", "tmp/dask-worker-space/keep.txt",
               f"tmp/{_HEX}/thesis.tex", "objects/ab/notes.txt", f"manifest/ab/{_HEX}.json.bak"]


@pytest.mark.parametrize("user_file", _USER_FILES)
def test_a_folder_with_a_user_file_is_not_adopted_and_gc_removes_nothing(project, tmp_path, user_file):
    """Names that merely start like the engine's (manifesto.txt, runs_2023.csv), or files where the engine
    never writes (anything under tmp/, a stray file in objects/): not a cache; run refuses it naming the file,
    and gc removes nothing there."""
    folder = tmp_path / "folder"
    f = folder / user_file
    f.parent.mkdir(parents=True)
    f.write_text("years of work\n")
    old = time.time() - 10 * 3600
    for p in [f, *f.parents]:   # old enough for any cleanup of temporary folders
        if folder in p.parents or p == folder:
            os.utime(p, (old, old))
    with pytest.raises(UserError, match="is not a stages cache") as err:
        run_quiet(project, cache_dir=str(folder))
    top = user_file.split("/")[0]
    assert (user_file if top in ("tmp", "objects", "manifest") else top) in str(err.value)
    with pytest.raises(UserError, match=CACHE_MARKER):
        api.gc([str(project)], cache_dir=str(folder))
    assert f.read_text() == "years of work\n"
    assert not (folder / CACHE_MARKER).exists()


def test_a_cache_from_before_the_marker_is_still_adopted(project, tmp_path):
    run_quiet(project)
    cache = tmp_path / "cache"
    (cache / CACHE_MARKER).unlink()
    shutil.rmtree(cache / "tmp", ignore_errors=True)
    s = run_quiet(project)
    assert (cache / CACHE_MARKER).is_file() and sum(x["executed"] for x in s["stages"].values()) == 0


def test_gc_does_not_follow_links_out_of_the_cache(project, tmp_path):
    """Links inside the cache (in place of an entry's data, of a generated dataset, of a temporary folder, or
    inside an entry) pointing outside it: gc removes the links at most, never what they point to."""
    run_quiet(project)
    run_quiet(project, overrides=["sigma=3"])                    # summary, rep of sigma=3: unreachable below
    cache = tmp_path / "cache"
    outside = tmp_path / "outside"
    outside.mkdir()
    for i in range(4):
        (outside / f"d{i}").mkdir()
        (outside / f"d{i}" / "keep.txt").write_text(f"precious {i}\n")
        (outside / f"d{i}" / ".complete").write_text("{}")
    plan = api.plan_pipeline(str(project), ["sigma=3"], quiet=True)
    gone = plan.stages["summary"].tasks[0].key                   # removed by gc: its data folder is a link
    shutil.rmtree(plan.store.object_path(gone), ignore_errors=True)
    os.makedirs(os.path.dirname(plan.store.object_path(gone)), exist_ok=True)
    os.symlink(outside / "d0", plan.store.object_path(gone))
    rep = plan.stages["rep"].tasks[0].key                        # removed: a link inside its files folder
    os.symlink(outside / "d1", os.path.join(plan.store.files_path(rep), "link"))
    (cache / "generated").mkdir(exist_ok=True)
    os.symlink(outside / "d2", cache / "generated" / _HEX)      # looks like a generated dataset
    (cache / "tmp").mkdir(exist_ok=True)
    os.symlink(outside / "d3", cache / "tmp" / uuid.uuid4().hex)  # looks like a temporary folder
    res = api.gc([str(project)])
    assert res["removed"] == 2
    for i in range(4):
        assert (outside / f"d{i}" / "keep.txt").read_text() == f"precious {i}\n"
        assert (outside / f"d{i}" / ".complete").is_file()
