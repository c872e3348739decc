"""Same inputs, same results: two cold runs of the default pipeline, in separate caches, one with 1 worker and
one with 2, give byte-identical `results --json` (issue 14 item 4: eigsh had no fixed start vector, and
accuracy.descriptor took five different values over eleven clean runs)."""
from __future__ import annotations

import shutil

import pytest

from tests.helpers import ROOT, cli


@pytest.mark.slow
def test_two_cold_runs_with_1_and_2_workers_give_identical_results(tmp_path):
    shutil.copy(ROOT / "pipeline.yaml", tmp_path / "pipeline.yaml")
    outputs = []
    for workers in (1, 2):
        cache, out = tmp_path / f"cache{workers}", tmp_path / f"out{workers}"
        res = cli(["run", "pipeline.yaml", "--cache", str(cache), "--out", str(out), "--workers", str(workers)],
                  cwd=tmp_path, timeout=900)
        assert res.returncode == 0, res.stderr[-3000:]
        res = cli(["results", "pipeline.yaml", "--cache", str(cache), "--json"], cwd=tmp_path)
        assert res.returncode == 0, res.stderr[-3000:]
        outputs.append(res.stdout)
    assert '"accuracy"' in outputs[0]
    assert outputs[0] == outputs[1]
