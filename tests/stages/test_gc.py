"""Sweeps and garbage collection: a sweep's points coexist in the cache; gc keeps what is reachable."""
from __future__ import annotations

import pytest

from stages import api

from tests.helpers import make_project


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
