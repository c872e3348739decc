"""Bad input fails fast with ``error: ...`` and exit code 2 (configuration / usage) or 1 (environment), never a
hang or a traceback: YAML aliases and duplicate keys, out-of-range options, folders given for files, bad grids,
unusable parameter values, a closed scheduler, unwritable folders, Ctrl-C; and --quiet still names failures."""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

from stages import api
from stages.config import load_pipeline
from stages.errors import PipelineError, UserError
from stages.store import Store

from tests.helpers import ROOT, SYNTHETIC_YAML, cli, cli_main, free_port, interrupted_run, make_project

BILLION_LAUGHS = "\n".join(
    ['a0: &a0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    + [f"a{i}: &a{i} [{','.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 10)]
    + ["stages: {s: {function: synthetic.summarize, params: {sigma: 1}}}", "params: {x: *a9}", ""])


@pytest.fixture()
def project(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return make_project(tmp_path)


def _fails(r: subprocess.CompletedProcess, code: int, *words: str) -> str:
    """Assert a clean failure: exit ``code``, an ``error:`` line containing ``words``, no traceback."""
    assert r.returncode == code, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    assert "error:" in r.stderr, r.stderr
    for w in words:
        assert w in r.stderr, (w, r.stderr)
    return r.stderr


# ---- YAML -------------------------------------------------------------------------------------------
@pytest.mark.timeout(60)   # fails fast: within a minute, as the subprocess it was run in before
def test_a_billion_laughs_file_fails_fast(tmp_path):
    p = tmp_path / "laughs.yaml"
    p.write_text(BILLION_LAUGHS)
    assert p.stat().st_size < 1024
    _fails(cli_main(["status", str(p)], tmp_path), 2, "aliases expand to more than")


def _reference_bomb(levels: int, as_list: bool) -> str:
    """``l{i}`` made of 10 references to ``l{i-1}``: 10**levels copies once expanded (a string, or nested lists)."""
    lines = ["params:", '  l0: "abcdefghij"']
    for i in range(1, levels + 1):
        refs = ["${l%d}" % (i - 1)] * 10
        lines.append(f"  l{i}: " + (json.dumps(refs) if as_list else '"' + "".join(refs) + '"'))
    return "\n".join(lines + [
        "stages: {s: {function: synthetic.summarize, inputs: {distances: d}, params: {sigma: 1}},",
        "         d: {function: synthetic.pair_distances, pairs: items}}",
        "datasets: {items: {files: 'data/*.txt', optional: true}}", ""])


@pytest.mark.timeout(60)
@pytest.mark.parametrize("as_list", [False, True], ids=["string", "list"])
def test_a_reference_bomb_fails_fast_naming_the_key(tmp_path, as_list):
    """11 levels of ten ${...} references each (10**11 copies): an error naming the parameter that grows too
    large, within seconds (not a hang), like the alias bomb."""
    p = tmp_path / "bomb.yaml"
    p.write_text(_reference_bomb(11, as_list))
    _fails(cli_main(["status", str(p)], tmp_path), 2, "expands to more than", "bomb.yaml:")  # first: a hang
    with pytest.raises(PipelineError, match="expands to more than") as err:                      # times out
        load_pipeline(str(p))
    assert err.value.key.startswith("params.l") and err.value.line


def test_references_used_many_times_still_resolve(tmp_path):
    p = tmp_path / "ok.yaml"
    p.write_text(_reference_bomb(3, as_list=False))
    assert load_pipeline(str(p)).params["l3"] == "abcdefghij" * 1000


def test_a_recursive_alias_is_refused(tmp_path):
    p = tmp_path / "rec.yaml"
    p.write_text("a: &a [*a]\nstages: {s: {function: synthetic.summarize}}\n")
    with pytest.raises(PipelineError, match="recursive"):
        load_pipeline(str(p))


def test_a_small_alias_still_works(tmp_path):
    p = tmp_path / "ok.yaml"
    p.write_text("params: {base: &b {sigma: 2.0}, copy: *b}\n"
                 "stages: {s: {function: synthetic.summarize, inputs: {distances: d}, params: {sigma: 1}},\n"
                 "         d: {function: synthetic.pair_distances, pairs: items}}\n"
                 "datasets: {items: {files: 'data/*.txt', optional: true}}\n")
    assert load_pipeline(str(p)).params["copy"] == {"sigma": 2.0}


def test_duplicate_keys_are_an_error_naming_both_lines(tmp_path):
    p = tmp_path / "dup.yaml"
    p.write_text("params:\n  sigma: 1\n  work: 2\n  sigma: 3\nstages: {s: {function: synthetic.summarize}}\n")
    with pytest.raises(PipelineError) as e:
        load_pipeline(str(p))
    assert "duplicate key 'sigma'" in str(e.value) and "line 2" in str(e.value) and "line 4" in str(e.value)


def test_a_binary_file_as_pipeline_is_a_clear_error(tmp_path):
    _fails(cli_main(["run", "/bin/ls", "--workers", "0"], tmp_path), 2, "not a text file")


# ---- names ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("text, what", [
    ("name: ../../x\nstages: {s: {function: synthetic.summarize}}\n", "pipeline"),
    ("stages: {../elsewhere/precious: {function: synthetic.summarize}}\n", "stage"),
    ("stages: {'my stage': {function: synthetic.summarize}}\n", "stage"),
    ("datasets: {'a/b': {file: x}}\nstages: {s: {function: synthetic.summarize}}\n", "dataset"),
])
def test_names_must_be_plain_identifiers(tmp_path, text, what):
    p = tmp_path / "names.yaml"
    p.write_text(text)
    with pytest.raises(PipelineError, match=f"{what} name .* is not a plain identifier"):
        load_pipeline(str(p))


# ---- options ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("workers", ["-1", "1000", "two"])
def test_workers_out_of_range_is_a_usage_error(project, tmp_path, workers):
    r = cli_main(["run", str(project), "--workers", workers], tmp_path)
    assert r.returncode == 2 and "--workers" in r.stderr and "Traceback" not in r.stderr, r.stderr


@pytest.mark.parametrize("command", [["run", "{p}", "--workers", "0", "--summary-json", "{d}"],
                                     ["report", "{p}", "--out", "{d}"]])
def test_a_folder_given_for_an_output_file_is_a_usage_error(project, tmp_path, command):
    folder = tmp_path / "somewhere"
    folder.mkdir()
    args = [a.format(p=project, d=folder) for a in command]
    r = cli_main(args, tmp_path)
    assert r.returncode == 2 and "is a folder" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert list(folder.iterdir()) == []  # no .tmp left behind


def test_atomic_write_to_a_folder_leaves_no_tmp(tmp_path):
    from stages.checksums import atomic_write_text

    with pytest.raises(IsADirectoryError):
        atomic_write_text(str(tmp_path), "x")
    assert not [p for p in tmp_path.parent.iterdir() if p.name.startswith(tmp_path.name + ".")]


@pytest.mark.parametrize("grid", ["sigma", "sigma=", "=1,2", "sigma=,"])
def test_bad_grid_syntax_is_a_usage_error(project, tmp_path, grid):
    _fails(cli_main(["sweep", str(project), "--grid", grid, "--workers", "0"], tmp_path), 2, "--grid")


def test_a_closed_scheduler_is_a_clear_error(project, tmp_path):
    address = f"tcp://127.0.0.1:{free_port()}"  # nothing listens there
    # 2 s instead of the default 10 s (dask retries a refused connection until then; the default: next test)
    err = _fails(cli(["run", str(project), "--scheduler", address], tmp_path, timeout=120,
                     env={"STAGES_SCHEDULER_TIMEOUT": "2"}), 1, address, "fix:", "within 2 s")
    assert "dask scheduler" in err


def test_the_scheduler_timeout_is_10_s_or_the_variable_and_a_bad_variable_is_a_clear_error(monkeypatch):
    from stages.execute import scheduler_timeout

    monkeypatch.delenv("STAGES_SCHEDULER_TIMEOUT", raising=False)
    assert scheduler_timeout() == 10.0
    monkeypatch.setenv("STAGES_SCHEDULER_TIMEOUT", " 2.5 ")
    assert scheduler_timeout() == 2.5
    for bad in ("ten", "0", "-3", "inf", "nan"):
        monkeypatch.setenv("STAGES_SCHEDULER_TIMEOUT", bad)
        with pytest.raises(UserError) as e:
            scheduler_timeout()
        assert f"STAGES_SCHEDULER_TIMEOUT='{bad}' is not a positive number of seconds" in str(e.value), bad


def test_a_malformed_scheduler_address_is_a_clear_error(project, tmp_path):
    _fails(cli_main(["run", str(project), "--scheduler", "not-an-address"], tmp_path), 1, "not-an-address")


# ---- parameter values the functions cannot use -------------------------------------------------------
def test_a_negative_generator_size_is_a_config_error(tmp_path):
    p = tmp_path / "g.yaml"
    p.write_text("generated: {chairs: {generator: generate.chairs, params: {n: -3}}}\n"
                 "datasets: {shapes: {files: '${generated.chairs}/*.obj'}}\n"
                 "stages: {views: {function: align.views, foreach: shapes, inputs: {files: shapes}}}\n")
    with pytest.raises(PipelineError) as e:
        load_pipeline(str(p))
    assert "generated.chairs.params" in str(e.value) and "'n' = -3" in str(e.value)


@pytest.mark.parametrize("n_views", [0, -4])
def test_n_views_below_one_is_a_config_error(tmp_path, monkeypatch, n_views):
    monkeypatch.chdir(ROOT)
    with pytest.raises(PipelineError) as e:
        load_pipeline("pipeline.yaml", [f"n_views={n_views}"], cache_dir=str(tmp_path / "c"))
    assert "stages.views.params" in str(e.value) and "n_views" in str(e.value)


def test_one_view_is_a_warning(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)
    load_pipeline("pipeline.yaml", ["n_views=1"], cache_dir=str(tmp_path / "c"))
    assert "metrics mean nothing" in capsys.readouterr().err


# ---- folders that cannot be used --------------------------------------------------------------------
def _snapshot(folder: Path) -> dict:
    return {str(p): (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*")}


def test_status_results_report_and_dry_run_write_nothing_to_the_cache(project, tmp_path):
    """What "works on a read-only cache" means: these commands never write there."""
    assert cli_main(["run", str(project), "--workers", "0"], tmp_path).returncode == 0
    (tmp_path / "data" / "s001.txt").write_text("changed\n")  # so the planner has something new to hash
    cache = tmp_path / "cache"
    before = _snapshot(cache)
    for command in (["status", str(project)], ["results", str(project)], ["run", str(project), "--dry-run"],
                    ["report", str(project), "--out", str(tmp_path / "r.html")]):
        r = cli_main(command, tmp_path)
        assert r.returncode in (0, 3) and "Traceback" not in r.stderr, r.stderr
    assert _snapshot(cache) == before


def test_run_on_an_unwritable_cache_is_a_clear_error(project, monkeypatch):
    monkeypatch.setattr(Store, "writable", lambda self: False)
    with pytest.raises(UserError, match="cannot write the cache folder"):
        api.run(str(project), workers=0, quiet=True)


def test_an_unwritable_output_folder_is_a_clear_error(project, tmp_path):
    (tmp_path / "blocker").write_text("a file where the output folder's parent should be\n")
    err = _fails(cli_main(["run", str(project), "--workers", "0", "--out", str(tmp_path / "blocker" / "out")],
                     tmp_path), 1, "output folder")
    assert "--out" in err
    r = cli_main(["run", str(project), "--workers", "0", "--summary-json", "s.json"], tmp_path)
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "s.json").read_text())
    assert sum(s["executed"] for s in summary["stages"].values()) == 0  # everything was stored the first time


# ---- failures and interruptions ---------------------------------------------------------------------
def test_quiet_still_prints_each_failure(project, tmp_path):
    r = cli_main(["run", str(project), "--workers", "0", "--quiet", "--set", "feat.fail_on=item 3 "], tmp_path)
    assert r.returncode == 1
    assert "FAILED feat[s003]" in r.stderr and "marker" in r.stderr, r.stderr


@pytest.mark.parametrize("exc, says", [
    (TimeoutError("timed out after 60 s."), "error: no answer in time (timed out after 60 s.)"),
    (PermissionError(13, "Permission denied", "/x/cache"), "error: cannot access /x/cache: Permission denied")])
def test_a_timeout_is_not_reported_as_a_file_that_cannot_be_accessed(exc, says, monkeypatch, capsys):
    """TimeoutError is an OSError: without a file name it is dask or a server that did not answer, not a path."""
    from stages import cli as stages_cli

    def run(*args, **kwargs):
        raise exc

    monkeypatch.setattr(api, "run", run)
    assert stages_cli.main(["run", "p.yaml"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(says) and "Traceback" not in err, err
    assert ("cannot access" in err) == isinstance(exc, PermissionError), err


@pytest.mark.e2e   # a whole multi-process run: .ci/run (pytest -m e2e), not the README's test command
def test_ctrl_c_to_the_process_group_shuts_down_without_worker_tracebacks(project, tmp_path):
    code, _, err = interrupted_run(project, tmp_path)
    assert code == 130, err
    assert "interrupted" in err and "Traceback" not in err, err


# ---- the dashboard ----------------------------------------------------------------------------------
def test_the_local_dashboard_listens_on_localhost_only(dask_client):
    sockets = dask_client.cluster.scheduler.http_server._sockets.values()
    hosts = {s.getsockname()[0] for s in sockets}
    assert hosts == {"127.0.0.1"}
    assert dask_client.cluster.dashboard_link.startswith("http://127.0.0.1:")


# ---- ~ and $VAR in path options -----------------------------------------------------------------------
def test_tilde_and_variables_in_path_options_are_expanded(project, tmp_path):
    """--cache '~/c', --out '$OUT_BASE/o', --summary-json '~/s.json' and report --out '${OUT_BASE}/r.html' (quoted,
    so no shell expanded them): the engine expands them, and creates no folder literally named '~' or '$...'."""
    home = tmp_path / "home"
    home.mkdir()
    env = {"HOME": str(home), "OUT_BASE": str(tmp_path / "base")}
    r = cli_main(["run", str(project), "--workers", "0", "--cache", "~/c", "--out", "$OUT_BASE/o",
             "--summary-json", "~/s.json"], tmp_path, env=env)
    assert r.returncode == 0, r.stderr
    assert (home / "c" / ".stages-cache").is_file() and (home / "s.json").is_file()
    assert (tmp_path / "base" / "o" / "metrics.json").is_file()
    r = cli_main(["report", str(project), "--cache", "~/c", "--results", "${OUT_BASE}/o",
                  "--out", "${OUT_BASE}/r.html"], tmp_path, env=env)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "base" / "r.html").is_file()
    assert not [n for n in os.listdir(tmp_path) if n.startswith(("~", "$"))]


def test_tilde_in_the_pipelines_cache_and_output_is_expanded(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    p = make_project(tmp_path, yaml_text=SYNTHETIC_YAML + "cache: ~/yc\noutput: ~/yo\n")
    pipe = load_pipeline(str(p))
    assert pipe.cache_dir == str(tmp_path / "home" / "yc") and pipe.output_dir == str(tmp_path / "home" / "yo")


@pytest.mark.parametrize("option", ["--cache", "--out", "--summary-json"])
def test_an_undefined_variable_in_a_path_option_is_refused(project, tmp_path, option):
    r = cli_main(["run", str(project), "--workers", "0", option, "$NO_SUCH_VARIABLE_XYZ/x"], tmp_path)
    assert r.returncode in (1, 2) and "Traceback" not in r.stderr, r.stderr
    assert "$NO_SUCH_VARIABLE_XYZ" in r.stderr and "not set" in r.stderr, r.stderr
    assert not [n for n in os.listdir(tmp_path) if n.startswith("$")]


def test_an_undefined_variable_in_the_pipelines_cache_names_the_key(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    p = make_project(tmp_path, yaml_text=SYNTHETIC_YAML + "cache: $NO_SUCH_VARIABLE_XYZ/c\n")
    with pytest.raises(PipelineError, match="NO_SUCH_VARIABLE_XYZ") as err:
        load_pipeline(str(p))
    assert err.value.key == "cache" and err.value.line
