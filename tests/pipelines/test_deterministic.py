"""Same inputs, same results: two cold runs of the default pipeline (every stage, the default counts), in
separate caches, one on 2 worker processes and one in the command's own process (``--workers 0``, with the
machine's default BLAS threads), give byte-identical `results --json` and byte-identical published files (the
eigensolvers start from a fixed vector: from ARPACK's random start, accuracy.descriptor took five different
values over eleven runs; in-process tasks once ran with every BLAS thread and gave 35 other alignment numbers,
stages/blas.py; the aligned meshes' zip once carried its files' times).

The 2-worker run is the session's shared audited cold run (``default_cold_run``, conftest.py); the in-process
run is made here, from nothing, in a folder of its own."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tests.helpers import ROOT, cli, machine_blas_environ

RUN_RECORD = ".stages-published.json"   # the engine's record of the publication (when, from which run)


def _published(folder: Path) -> dict[str, bytes]:
    """{relative path: bytes} of the stages' files the run record of ``folder`` lists, and metrics.json (not what
    other commands published there since: another e2e test writes report.html into the shared run's folder)."""
    record = json.loads((folder / RUN_RECORD).read_text())["data"]
    names = {name for files in record["stages"].values() for name in files} | {"metrics.json"}
    return {name: (folder / name).read_bytes() for name in sorted(names)}


@pytest.mark.e2e
def test_a_cold_run_in_process_gives_the_bytes_of_a_run_on_2_workers(default_cold_run, tmp_path, monkeypatch):
    assert default_cold_run.res.returncode == 0, default_cold_run.res.stderr[-3000:]
    shutil.copy(ROOT / "pipeline.yaml", tmp_path / "pipeline.yaml")
    cache, out = tmp_path / "cache0", tmp_path / "out0"
    machine_blas_environ(monkeypatch)   # the machine's threads, as before tests/conftest.py set one
    res = cli(["run", "pipeline.yaml", "--cache", str(cache), "--out", str(out), "--workers", "0", "--quiet"],
              cwd=tmp_path, timeout=1200)
    monkeypatch.undo()
    assert res.returncode == 0, res.stderr[-3000:]
    outputs = []
    for folder, args in ((default_cold_run.folder, []), (tmp_path, ["--cache", str(cache)])):
        res = cli(["results", "pipeline.yaml", "--json", *args], cwd=folder)
        assert res.returncode == 0, res.stderr[-3000:]
        outputs.append(res.stdout)
    assert '"accuracy"' in outputs[0]
    assert outputs[0] == outputs[1]
    two_workers, in_process = _published(default_cold_run.folder / "results" / "demo"), _published(out)
    assert "align_export/aligned_meshes.zip" in two_workers and "metrics.json" in two_workers
    assert sorted(two_workers) == sorted(in_process)
    assert [name for name in two_workers if two_workers[name] != in_process[name]] == []
