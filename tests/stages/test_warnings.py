"""A metrics stage's "warnings" (sentences a user should act on): gathered per stage under "_warnings" by
``results.metrics`` (two stages never overwrite each other's), printed by ``run`` and ``results``, and shown on
the report's first screen."""
from __future__ import annotations

from tests.helpers import SYNTHETIC_YAML, cli, make_project
from stages import api
from stages.report import write_report

TWO_SUMMARIES = SYNTHETIC_YAML + """\
  strict:
    function: synthetic.summarize
    inputs: {distances: dist}
    params: {sigma: 0.5, warn_below: 2.0}
    metrics: true
"""


def test_warnings_of_two_metrics_stages_are_kept_apart_printed_and_reported(tmp_path, monkeypatch):
    path = make_project(tmp_path, n=4, yaml_text=TWO_SUMMARIES)
    monkeypatch.chdir(tmp_path)                 # the pipeline's paths (data/, cache/) are relative to it
    run = cli(["run", "p.yaml", "--workers", "0", "--set", "summary.warn_below=2.0"], cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "warning (summary): mean affinity" in run.stderr and "warning (strict): mean affinity" in run.stderr
    plan = api.plan_pipeline(str(path), ["summary.warn_below=2.0"], quiet=True)
    m = api.metrics(plan)
    assert set(m["_warnings"]) == {"summary", "strict"} and "warnings" not in m
    assert "at sigma 1.0" in m["_warnings"]["summary"][0] and "at sigma 0.5" in m["_warnings"]["strict"][0]
    res = cli(["results", "p.yaml", "--set", "summary.warn_below=2.0"], cwd=tmp_path)
    assert res.returncode == 0 and res.stdout.count("warning (") == 2, res.stdout
    html = open(write_report(str(path), ["summary.warn_below=2.0"]), encoding="utf-8").read()
    first_screen = html[:html.index("run details")]
    assert 'class="bad warning">summary: mean affinity' in first_screen
    assert 'class="bad warning">strict: mean affinity' in first_screen
