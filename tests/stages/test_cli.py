"""The CLI end to end: kill -9 and resume, concurrent runs, code changes, an external dask cluster."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from stages import api

from tests.helpers import ROOT, SYNTHETIC_YAML, ExternalCluster, cli, cli_main, make_project, plugins_env


def _summary(path: Path) -> dict:
    return json.loads(path.read_text())


def _executed(s: dict) -> dict:
    return {k: v["executed"] for k, v in s["stages"].items()}


def _final_values(project: Path, cwd: Path, overrides=()) -> dict:
    os.chdir(cwd)
    plan = api.plan_pipeline(str(project), list(overrides), quiet=True)
    out = {}
    for name, sp in plan.stages.items():
        for t in sp.tasks:
            out[(name, t.label)] = plan.store.get(t.key)
    return out


def test_run_dry_run_and_summary_json(tmp_path):
    project = make_project(tmp_path)
    res = cli(["run", "p.yaml", "--summary-json", "s.json"], cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert _executed(_summary(tmp_path / "s.json"))["feat"] == 12
    assert "done in" in res.stdout
    # the read-only commands in this process (the same output as a process: test_cli_in_process.py)
    res = cli_main(["run", "p.yaml", "--set", "sigma=3", "--dry-run"], cwd=tmp_path)
    assert res.returncode == 0
    assert "summary: 1 of 1 task(s) would run" in res.stdout and "param sigma: 1.0 -> 3.0" in res.stdout
    assert "feat: 0 of 12 task(s) would run (all cached)" in res.stdout
    res = cli_main(["status", "p.yaml", "--set", "sigma=3"], cwd=tmp_path)
    assert "param sigma: 1.0 -> 3.0" in res.stdout
    res = cli_main(["results", "p.yaml", "--json"], cwd=tmp_path)
    assert json.loads(res.stdout)["n_items"] == 12
    res = cli_main(["results", "p.yaml", "--set", "sigma=7"], cwd=tmp_path)
    assert res.returncode == 3 and "not computed yet" in res.stdout


def _assert_same_final_values(project, folder, clean, work: str) -> None:
    """The stored final values of ``project`` (run in ``folder``) equal those of the same pipeline run cleanly in
    ``clean``, bit for bit."""
    cwd = os.getcwd()
    try:
        a = _final_values(project, folder, [f"work={work}"])
        b = _final_values(clean / "p.yaml", clean, [f"work={work}"])
    finally:
        os.chdir(cwd)
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], np.ndarray):
            np.testing.assert_array_equal(a[k], b[k])
        else:
            assert a[k] == b[k]


@pytest.mark.e2e   # a whole multi-process run: .ci/run (pytest -m e2e), not the README's test command
def test_kill_9_then_resume_equals_uninterrupted_run(tmp_path):
    work = "100"  # ms per item: the run takes a few seconds
    slow = tmp_path / "killed"
    slow.mkdir()
    project = make_project(slow, n=40)
    proc = subprocess.Popen([sys.executable, "-m", "stages", "run", "p.yaml", "--set", f"work={work}", "--quiet"],
                            cwd=slow, env={**os.environ, "PYTHONPATH": str(ROOT)}, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    manifest = slow / "cache" / "manifest"
    deadline = time.time() + 120
    while time.time() < deadline:
        n = sum(len(f) for _, _, f in os.walk(manifest)) if manifest.exists() else 0
        if n >= 10:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done_before = sum(len(f) for _, _, f in os.walk(manifest))
    assert 10 <= done_before < 40 + 55 + 2, "the kill should land mid-run"
    res = cli(["run", "p.yaml", "--set", f"work={work}", "--summary-json", "s.json"], cwd=slow)
    assert res.returncode == 0, res.stderr
    s = _summary(slow / "s.json")
    assert s["stages"]["feat"]["cached"] >= 1 and s["stages"]["feat"]["executed"] < 40
    # an uninterrupted run in a fresh folder gives identical results
    clean = tmp_path / "clean"
    clean.mkdir()
    make_project(clean, n=40)
    assert cli_main(["run", "p.yaml", "--set", f"work={work}", "--workers", "0", "--quiet"], cwd=clean).returncode == 0
    _assert_same_final_values(project, slow, clean, work)


def _worker_processes(pid: int) -> list:
    """[(user CPU seconds, process)] of the dask worker processes (started by the nannies) under ``pid``; a child
    that exits meanwhile, or is a zombie not yet reaped, is left out (reading it raised psutil.ZombieProcess)."""
    import psutil

    out = []
    try:
        children = psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return out
    for child in children:
        try:
            if "spawn_main" in " ".join(child.cmdline()):
                out.append((child.cpu_times().user, child))
        except psutil.Error:
            continue
    return out


@pytest.mark.e2e   # a whole multi-process run: .ci/run (pytest -m e2e), not the README's test command
def test_a_worker_killed_mid_run_then_resume_equals_uninterrupted_run(tmp_path):
    """SIGKILL to one dask worker process (not the CLI) while tasks run: the run finishes (the task is run again
    elsewhere, or reported failed), nothing stored is lost, and a resumed run gives the values of an
    uninterrupted one."""
    work = "150"
    slow = tmp_path / "killed"
    slow.mkdir()
    project = make_project(slow, n=24)
    proc = subprocess.Popen([sys.executable, "-m", "stages", "run", "p.yaml", "--set", f"work={work}", "--quiet",
                             "--workers", "2"], cwd=slow, env={**os.environ, **plugins_env()},
                            start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    manifest = slow / "cache" / "manifest"
    deadline = time.time() + 180
    killed = None
    try:
        while time.time() < deadline and killed is None:
            n = sum(len(f) for _, _, f in os.walk(manifest)) if manifest.exists() else 0
            workers = _worker_processes(proc.pid)
            if n >= 4 and workers:
                killed = max(workers, key=lambda w: w[0])[1]  # the busier one: it runs a task
                killed.send_signal(signal.SIGKILL)
            time.sleep(0.05)
        assert killed is not None, "no worker process found mid-run"
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode in (0, 1) and "Traceback" not in err, err
    done_before = sum(len(f) for _, _, f in os.walk(manifest))
    assert done_before >= 4
    res = cli(["run", "p.yaml", "--set", f"work={work}", "--workers", "0", "--summary-json", "s.json"], cwd=slow)
    assert res.returncode == 0, res.stderr
    assert _summary(slow / "s.json")["stages"]["feat"]["cached"] >= 4
    clean = tmp_path / "clean"
    clean.mkdir()
    make_project(clean, n=24)
    assert cli_main(["run", "p.yaml", "--set", f"work={work}", "--workers", "0", "--quiet"], cwd=clean).returncode == 0
    _assert_same_final_values(project, slow, clean, work)
    assert (slow / "results" / "syn" / "rep" / "summary.txt").read_bytes() == \
        (clean / "results" / "syn" / "rep" / "summary.txt").read_bytes()


@pytest.mark.e2e   # a whole multi-process run: .ci/run (pytest -m e2e), not the README's test command
def test_two_runs_at_once_on_one_cache(tmp_path):
    make_project(tmp_path, n=30)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    procs = [subprocess.Popen([sys.executable, "-m", "stages", "run", "p.yaml", "--set", "work=30",
                               "--summary-json", f"s{i}.json", "--quiet"], cwd=tmp_path, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    res = cli_main(["run", "p.yaml", "--set", "work=30", "--summary-json", "s2.json"], cwd=tmp_path)
    assert sum(_executed(_summary(tmp_path / "s2.json")).values()) == 0
    res = cli_main(["results", "p.yaml", "--set", "work=30", "--json"], cwd=tmp_path)
    assert json.loads(res.stdout)["n_items"] == 30


PLUGIN = '''
import numpy as np
from stages.registry import register

def helper(x):
    return x * 2.0

@register("plug.double", fanout="item")
def double(features):
    """Double a feature."""
    return helper(np.asarray(features))

@register("plug.total", fanout="once")
def total(items):
    return {"total": float(sum(float(np.sum(v)) for v in items.values()))}
'''

PLUGIN_YAML = SYNTHETIC_YAML + """  doubled:
    function: plug.double
    foreach: feat
    inputs: {features: feat}
  total:
    function: plug.total
    inputs: {items: doubled}
    metrics: true
"""


def test_code_change_reruns_only_dependent_stages(tmp_path):
    make_project(tmp_path, n=8, yaml_text=PLUGIN_YAML)
    plug = tmp_path / "plugmod"
    plug.mkdir()
    (plug / "myplugin.py").write_text(PLUGIN)
    env = plugins_env("myplugin")
    env["PYTHONPATH"] += os.pathsep + str(plug)
    # each run a new process (the code is edited between runs), computing in that process (--workers 0): the
    # keys are planned there, whichever processes then compute (the default 2 workers: the other tests here)
    assert cli(["run", "p.yaml", "--quiet", "--workers", "0"], cwd=tmp_path, env=env).returncode == 0
    # docstrings and comments do not count as code
    (plug / "myplugin.py").write_text(PLUGIN.replace('"""Double a feature."""', '"""Twice."""  # comment'))
    res = cli(["run", "p.yaml", "--summary-json", "a.json", "--quiet", "--workers", "0"], cwd=tmp_path, env=env)
    assert sum(_executed(_summary(tmp_path / "a.json")).values()) == 0
    # a change in a helper the stage function calls reruns that stage and what follows it only
    (plug / "myplugin.py").write_text(PLUGIN.replace("x * 2.0", "x * 3.0"))
    res = cli(["run", "p.yaml", "--dry-run"], cwd=tmp_path, env=env)
    assert "doubled: 8 of 8 task(s) would run" in res.stdout and "code changed: myplugin.helper" in res.stdout
    res = cli(["run", "p.yaml", "--summary-json", "b.json", "--workers", "0"], cwd=tmp_path, env=env)
    assert res.returncode == 0, res.stderr
    assert "doubled: 8 tasks (code changed: myplugin.helper)" in res.stderr   # run says why, too
    ex = _executed(_summary(tmp_path / "b.json"))
    assert ex == {"feat": 0, "dist": 0, "summary": 0, "rep": 0, "doubled": 8, "total": 1}


@pytest.mark.e2e   # a whole multi-process run: .ci/run (pytest -m e2e), not the README's test command
def test_pipeline_on_an_external_dask_cluster(tmp_path):
    make_project(tmp_path, n=10)
    with ExternalCluster(tmp_path, n_workers=2) as cluster:
        res = cli(["run", "p.yaml", "--scheduler", cluster.address, "--summary-json", "s.json"], cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        assert _executed(_summary(tmp_path / "s.json"))["feat"] == 10
        manifests = [json.loads(p.read_text()) for p in (tmp_path / "cache" / "manifest").rglob("*.json")]
        assert len({m["info"]["pid"] for m in manifests}) == 2  # both external workers did work


def test_version_and_the_stages_console_script(tmp_path):
    """``--version`` prints the package version; pyproject.toml declares a ``stages`` script that is the CLI."""
    import importlib
    import tomllib

    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    version = pyproject["project"]["version"]
    res = cli(["--version"], cwd=tmp_path)
    assert res.returncode == 0 and res.stdout.strip() == f"stages {version}", res
    module, _, func = pyproject["project"]["scripts"]["stages"].partition(":")
    main = getattr(importlib.import_module(module), func)
    make_project(tmp_path, n=4)
    script = ("import sys; sys.argv[0] = 'stages'; "
              f"from {module} import {func}; sys.exit({func}())")   # what the installed script does
    res = subprocess.run([sys.executable, "-c", script, "run", "p.yaml", "summary", "--workers", "0"], cwd=tmp_path,
                         env={**os.environ, **plugins_env()}, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "summary: 1 task (no earlier run of this pipeline)" in res.stderr and "rep" not in res.stdout
    assert callable(main)


@pytest.mark.parametrize("columns", [80, 100])
def test_functions_fits_the_terminal_with_whole_first_sentences(tmp_path, columns):
    """``functions`` wraps to COLUMNS and shows each docstring's whole first sentence (not its first line)."""
    from stages.cli import first_sentence

    assert first_sentence("Per method: the template\n    and 4 poses (e.g. the best). More.\n\nArgs: x") == \
        "Per method: the template and 4 poses (e.g. the best)."
    res = cli_main(["functions"], cwd=tmp_path, env={"COLUMNS": str(columns)})
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert lines and max(len(x) for x in lines) <= columns
    assert max(len(x) for x in lines) > columns - 15                 # wrapped at the width, not far below it
    docs, current = [], None
    for line in lines:                                               # a description: the indented lines after a name
        if line.startswith("    ") and not line.startswith("     "):   # (a name's wrapped params: 8 spaces)
            current = (current + " " if current else "") + line.strip()
        elif not line.startswith(" "):
            if current:
                docs.append(current)
            current = None
    assert docs and all(d.endswith((".", ":", ")", "}", "]")) for d in docs), [d for d in docs if d[-1] not in ".:)}]"]
