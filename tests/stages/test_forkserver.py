"""stages/forkserver.py: a run's local workers are forked from one server that imported what they need, started
afresh for each run (fresh code), with the workers' environment, and stopped when the run ends."""
from __future__ import annotations

import os
import subprocess
import sys

import psutil

from stages import api, forkserver, registry
from stages.execute import worker_process_environ
from tests.helpers import machine_blas_environ, make_project

FACTS_YAML = """\
name: facts
datasets:
  items: {files: "data/*.txt"}
stages:
  facts: {function: synthetic.worker_facts, foreach: items, inputs: {path: items}, params: {run: 0}}
"""


def _servers() -> list[psutil.Process]:
    """This process's fork server children (multiprocessing.forkserver), alive."""
    return [c for c in psutil.Process().children() if c.is_running() and c.status() != psutil.STATUS_ZOMBIE
            and "multiprocessing.forkserver" in " ".join(c.cmdline())]


def _facts(project, cache, run: int) -> list[dict]:
    api.run(str(project), overrides=[f"facts.run={run}"], workers=2, quiet=True, cache_dir=str(cache))
    return [api.result(str(project), "facts", f"s{i:03d}", params={"facts.run": run}, cache_dir=str(cache))
            for i in range(2)]


def test_a_runs_workers_are_forked_from_a_fresh_server_with_their_environment_which_stops_at_the_end(
        tmp_path, monkeypatch):
    machine_blas_environ(monkeypatch)   # the workers' one BLAS thread must come from the engine, not the tests
    # this test process may have imported the application for other tests, and the workers would then import it
    # at their start (stages.worker_boot): what the server itself preloads is what is checked here
    monkeypatch.setattr(registry, "imported_plugins", lambda: [])
    monkeypatch.chdir(tmp_path)
    project = make_project(tmp_path, n=2, yaml_text=FACTS_YAML)
    first = _facts(project, tmp_path / "cache", run=0)
    assert not _servers() and not forkserver.holding(), "the server outlived the run"
    second = _facts(project, tmp_path / "cache", run=1)
    for facts in first + second:
        assert "multiprocessing.forkserver" in facts["parent_cmd"] and facts["parent"] != os.getpid()
        assert facts["env"]["OMP_NUM_THREADS"] == facts["env"]["OPENBLAS_NUM_THREADS"] == "1"
        assert facts["blas_threads"] == 1
        assert facts["application"] == [], "the server preloads only the plugins the pipeline names"
        assert facts["env"]["PYTHONPATH"] == os.environ.get("PYTHONPATH"), "the user's PYTHONPATH is put back"
    # dask's spawned workers hash strings with PYTHONHASHSEED 6640: a forked worker does the same
    spawned_hash = subprocess.run([sys.executable, "-c", "print(hash('stages'))"], capture_output=True, text=True,
                                  env={**os.environ, "PYTHONHASHSEED": "6640"}, check=True).stdout.strip()
    assert {f["hash"] for f in first + second} == {int(spawned_hash)}
    assert {f["env"]["PYTHONHASHSEED"] for f in first + second} == {"6640"}
    # each run had its own server: code imported by an earlier run's server never runs in a later run
    assert {f["parent"] for f in first}.isdisjoint({f["parent"] for f in second})


def test_without_a_server_the_workers_are_spawned_and_the_run_is_the_same(tmp_path, monkeypatch):
    def refuse(*_a, **_k):
        raise OSError("no fork server here")

    monkeypatch.setattr(forkserver, "_start_server", refuse)
    monkeypatch.chdir(tmp_path)
    project = make_project(tmp_path, n=2, yaml_text=FACTS_YAML)
    facts = _facts(project, tmp_path / "cache", run=0)
    assert all("multiprocessing.forkserver" not in f["parent_cmd"] for f in facts)
    assert {f["env"]["OMP_NUM_THREADS"] for f in facts} == {"1"} and not _servers()


def test_holders_share_one_server_and_the_last_to_let_go_stops_it():
    environ = worker_process_environ()
    ours = dict(os.environ)
    assert forkserver.acquire([], environ)
    try:
        assert dict(os.environ) == ours, "the server's variables leaked into this process"
        (server,) = _servers()
        assert forkserver.acquire(["not-a-plugin"], environ) and _servers() == [server]
        forkserver.release()
        assert forkserver.holding() and server.is_running()
    finally:
        forkserver.release()
    assert not forkserver.holding() and not _servers()
    forkserver.release()   # one more release than acquires: nothing happens
    assert not forkserver.holding()


def test_the_next_holder_after_a_stop_gets_a_new_server():
    environ = worker_process_environ()
    with forkserver.held([], environ) as got:
        assert got
        (first,) = _servers()
    with forkserver.held([], environ) as got:
        assert got
        (second,) = _servers()
    assert first.pid != second.pid and not _servers()
    with forkserver.held(None, environ) as got:   # None: nothing to start
        assert not got and not _servers()
