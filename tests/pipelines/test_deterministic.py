"""Same inputs, same results: two cold runs of the default pipeline (every stage, the default counts), in
separate caches, one with 2 workers and one with 1, give byte-identical `results --json` (the eigensolvers start
from a fixed vector: from ARPACK's random start, accuracy.descriptor took five different values over eleven runs).

The 2-worker run is the session's shared audited cold run (``default_cold_run``, conftest.py); the 1-worker run
is made here, from nothing, in a folder of its own."""
from __future__ import annotations

import shutil

import pytest

from tests.helpers import ROOT, cli


@pytest.mark.e2e
def test_two_cold_runs_with_1_and_2_workers_give_identical_results(default_cold_run, tmp_path):
    assert default_cold_run.res.returncode == 0, default_cold_run.res.stderr[-3000:]
    shutil.copy(ROOT / "pipeline.yaml", tmp_path / "pipeline.yaml")
    cache, out = tmp_path / "cache1", tmp_path / "out1"
    res = cli(["run", "pipeline.yaml", "--cache", str(cache), "--out", str(out), "--workers", "1", "--quiet"],
              cwd=tmp_path, timeout=1200)
    assert res.returncode == 0, res.stderr[-3000:]
    outputs = []
    for folder, args in ((default_cold_run.folder, []), (tmp_path, ["--cache", str(cache)])):
        res = cli(["results", "pipeline.yaml", "--json", *args], cwd=folder)
        assert res.returncode == 0, res.stderr[-3000:]
        outputs.append(res.stdout)
    assert '"accuracy"' in outputs[0]
    assert outputs[0] == outputs[1]
