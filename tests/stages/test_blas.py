"""``one_blas_thread``: tasks and generators run in the engine's own process get one BLAS/OpenMP thread, as in a
local worker, so a result does not depend on where it ran (stages/blas.py)."""
from __future__ import annotations

import os

import threadpoolctl

from stages import api
from stages.blas import BLAS_THREAD_ENVIRON, one_blas_thread
from tests.helpers import cli, make_project

BLAS_YAML = """\
name: blas
generated:
  things: {generator: synthetic.write_blas_threads, params: {n: 2}}
datasets:
  items: {files: "${generated.things}/*.txt"}
stages:
  threads: {function: synthetic.blas_threads, foreach: items, inputs: {path: items}}
"""


def test_tasks_and_generators_run_in_this_process_get_one_blas_thread_as_in_a_worker(tmp_path):
    """A multi-threaded BLAS gives other last bits than a worker's one thread (stages/blas.py); the subprocess
    asks for 2 threads, as on a machine with 2 cores and no variables set (the tests' conftest sets 1)."""
    p = make_project(tmp_path, n=0, yaml_text=BLAS_YAML)
    env = dict.fromkeys(BLAS_THREAD_ENVIRON, "2")
    res = cli(["run", str(p), "--workers", "0", "--quiet", "--cache", "cache"], cwd=tmp_path, env=env)
    assert res.returncode == 0, res.stderr[-3000:]
    seen = [api.result(str(p), "threads", f"item{i:03d}", cache_dir=str(tmp_path / "cache")) for i in range(2)]
    assert seen == [{"generator": 1, "task": 1}] * 2


def test_one_blas_thread_sets_the_variables_for_its_body_and_puts_back_those_it_found(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    with one_blas_thread():
        assert {var: os.environ.get(var) for var in BLAS_THREAD_ENVIRON} == BLAS_THREAD_ENVIRON
        assert max(pool["num_threads"] for pool in threadpoolctl.threadpool_info()) == 1
    assert os.environ.get("OMP_NUM_THREADS") == "3" and "OPENBLAS_NUM_THREADS" not in os.environ
