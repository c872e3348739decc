"""pipelines/scale.yaml end to end on a real dask.distributed cluster (scheduler and two workers as separate
processes on 127.0.0.1), with a temporary cache: 12 generated chairs on a sparse candidate graph must be aligned
exactly, with only the candidate pairs computed."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import ROOT, ExternalCluster

PIPELINE = ROOT / "pipelines" / "scale.yaml"


def _stages(args: list[str], cwd: Path, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stages", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120)


@pytest.mark.e2e
def test_scale_pipeline_on_an_external_dask_cluster(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cache, out = tmp_path / "cache", tmp_path / "out"
    common = ["--set", "n=12", "--set", "k=3", "--set", "n_random=1", "--cache", str(cache)]
    with ExternalCluster(tmp_path, n_workers=2) as cluster:
        res = _stages(["run", str(PIPELINE), *common, "--out", str(out), "--scheduler", cluster.address,
                       "--summary-json", str(tmp_path / "s.json")], ROOT, env)
        assert res.returncode == 0, res.stderr
        stages = json.loads((tmp_path / "s.json").read_text())["stages"]
        assert stages["views"]["executed"] == 12 and stages["hog"]["executed"] == 12
        assert stages["descriptor"]["executed"] == 12 and stages["candidates"]["executed"] == 1
        assert stages["solve"]["executed"] == 1 and stages["evaluate"]["executed"] == 1
        # both external worker processes did work (each task's manifest records its worker's pid)
        manifests = [json.loads(p.read_text()) for p in (cache / "manifest").rglob("*.json")]
        assert len({m["info"]["pid"] for m in manifests if "pid" in m.get("info", {})}) == 2
        res = _stages(["results", str(PIPELINE), *common, "--json"], ROOT, env)
        assert res.returncode == 0, res.stderr
        m = json.loads(res.stdout)
        assert m["ground_truth"]["n"] == 12 and m["ground_truth"]["exact"] == 1.0
        assert m["n_shapes"] == 12
        # only the candidate graph's pairs: at most 3 nearest + 1 random partner per shape, of 66
        assert m["graph"] == "candidates" and m["pairs_total"] == 66
        assert 12 <= m["pairs_computed"] <= 48 and m["pairs_fraction"] == m["pairs_computed"] / 66
