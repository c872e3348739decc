"""pipelines/scale.yaml end to end on a real dask.distributed cluster (scheduler and two workers as separate
processes on 127.0.0.1), with a temporary cache: 12 generated chairs must be aligned exactly."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from tests.helpers import ROOT, ExternalCluster

PIPELINE = ROOT / "pipelines" / "scale.yaml"


def _stages(args: list[str], cwd: Path, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stages", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120)


def test_scale_pipeline_on_an_external_dask_cluster(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cache, out = tmp_path / "cache", tmp_path / "out"
    common = ["--set", "n=12", "--cache", str(cache)]
    with ExternalCluster(tmp_path, n_workers=2) as cluster:
        res = _stages(["run", str(PIPELINE), *common, "--out", str(out), "--scheduler", cluster.address,
                       "--summary-json", str(tmp_path / "s.json")], ROOT, env)
        assert res.returncode == 0, res.stderr
        stages = json.loads((tmp_path / "s.json").read_text())["stages"]
        assert stages["views"]["executed"] == 12 and stages["hog"]["executed"] == 12
        assert stages["solve"]["executed"] == 1 and stages["evaluate"]["executed"] == 1
        # both external worker processes did work (each task's manifest records its worker's pid)
        manifests = [json.loads(p.read_text()) for p in (cache / "manifest").rglob("*.json")]
        assert len({m["info"]["pid"] for m in manifests if "pid" in m.get("info", {})}) == 2
        res = _stages(["results", str(PIPELINE), *common, "--json"], ROOT, env)
        assert res.returncode == 0, res.stderr
        m = json.loads(res.stdout)
        assert m["ground_truth"]["n"] == 12 and m["ground_truth"]["exact"] == 1.0
        assert m["n_shapes"] == 12
