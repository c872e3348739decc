"""Helpers to build small synthetic pipelines for engine tests."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SYNTHETIC_YAML = """\
name: syn
params:
  sigma: 1.0
  root: data
  work: 0
datasets:
  items: {files: "${root}/*.txt"}
stages:
  feat:
    function: synthetic.features
    foreach: items
    inputs: {path: items}
    params: {work: "${work}"}
  dist:
    function: synthetic.pair_distances
    pairs: feat
    tile: 4
  summary:
    function: synthetic.summarize
    inputs: {distances: dist}
    params: {sigma: "${sigma}"}
    metrics: true
  rep:
    function: synthetic.report
    inputs: {summary: summary}
"""


def make_project(tmp: Path, n: int = 12, yaml_text: str = SYNTHETIC_YAML) -> Path:
    """Write ``n`` item files under tmp/data and the pipeline tmp/p.yaml; returns the pipeline path."""
    (tmp / "data").mkdir(parents=True, exist_ok=True)
    for i in range(n):
        (tmp / "data" / f"s{i:03d}.txt").write_text(f"item {i} content {i * 7919 % 1000}\n")
    p = tmp / "p.yaml"
    p.write_text(yaml_text)
    return p


def cli(args: list[str], cwd: Path, env: dict | None = None, timeout: float = 300, **kw) -> subprocess.CompletedProcess:
    """Run ``python -m stages ARGS`` in ``cwd``."""
    full_env = dict(os.environ)
    full_env["PYTHONPATH"] = os.pathsep.join([str(ROOT), full_env.get("PYTHONPATH", "")])
    full_env.update(env or {})
    return subprocess.run([sys.executable, "-m", "stages", *args], cwd=cwd, env=full_env, capture_output=True,
                          text=True, timeout=timeout, **kw)


def executed(summary: dict) -> dict[str, int]:
    return {name: s["executed"] for name, s in summary["stages"].items()}
