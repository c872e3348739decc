"""``sweep``'s printed table: headline measures only, as wide as the terminal (COLUMNS) at most, headers
group.measure, notes wrapped, the best per column starred;
``--metrics`` picks columns (keys or patterns), ``--csv`` writes the full table; plus the progress estimate."""
from __future__ import annotations

import csv
import io
import json
import os

import pytest

from stages.errors import PipelineError
from stages.execute import Progress
from stages.sweep import MAX_WIDTH, figure_name, format_table, headline_columns, plot_sweep, write_table
from tests.helpers import SYNTHETIC_YAML, cli_main, loaded_plugin, make_project, plugins_env

PLUGIN = "sweep_table_plugin"
PLUGIN_SOURCE = '''
from stages.registry import Headline, Measure, Plugin, register

PLUGIN = Plugin(name="sweep_table", packages=(__name__,),
                headlines=(Headline(group="g", title="per method", rows_from="score",
                                    measures=(Measure("score", "score.{row}"),
                                              Measure("error", "error.{row}", better="min"))),))


@register("synthetic.sweep_scores", group="g")
def scores(summary, *, shift: float = 0.0):
    """Many scalar metrics (as a real evaluation gives): 2 headline methods and 150 per-item values."""
    a = float(summary["mean_affinity"])
    return {"score": {"m1": round(a + shift, 6), "m2": 0.5}, "error": {"m1": round(1 - a, 6), "m2": 0.4},
            "per_item": {f"item{i:03d}": {"value": i * a} for i in range(150)},
            **{f"count_{i:03d}": i for i in range(150)}}
'''

EXTRA = """\
  scores:
    function: synthetic.sweep_scores
    inputs: {summary: summary}
    metrics: true
"""


def _rows(values_m1, errors_m1):
    return [{"point": {"sigma": str(i)}, "metrics": {"score": {"m1": v, "m2": 0.5}, "error": {"m1": e, "m2": 0.4},
                                                     **{f"count_{j:03d}": j for j in range(150)}}}
            for i, (v, e) in enumerate(zip(values_m1, errors_m1))]


def test_format_table_fits_and_marks_the_best():
    rows = _rows([0.9, 0.7, 0.95], [0.1, 0.3, 0.2])
    head = {"columns": ["score.m1", "score.m2", "error.m1"], "better": {"score.m1": "max", "error.m1": "min"}}
    lines = format_table(rows, head).splitlines()
    assert lines[0].split() == ["sigma", "score.m1", "score.m2", "error.m1"]
    body = [line.split() for line in lines[2:5]]
    assert [r[1] for r in body] == ["0.9", "0.7", "0.95*"]          # max
    assert [r[3] for r in body] == ["0.1*", "0.3", "0.2"]           # min
    assert [r[2] for r in body] == ["0.5", "0.5", "0.5"]            # no direction: no mark
    # every scalar metric (152 columns) does not fit: shortened, cut, and said so
    text = format_table(rows, None, width=MAX_WIDTH)
    assert max(len(x) for x in text.splitlines()) <= MAX_WIDTH
    assert "more column(s) do not fit" in text


@pytest.mark.parametrize("columns", [80, 100])
def test_format_table_fits_the_terminal(columns, monkeypatch):
    """COLUMNS sets the width: the table, its wrapped column legend and notes fit; headers say group.measure."""
    monkeypatch.setenv("COLUMNS", str(columns))
    keys = [f"correspondence.seed_stability_{k}.min" for k in range(3)] + ["alignment.azimuth.exact",
                                                                          "dense.mobius.mean_error"]
    rows = [{"point": {"align.sigma_scale": str(i)},
             "metrics": {"correspondence": {f"seed_stability_{k}": {"min": 123456.789 + i + k} for k in range(3)},
                         "alignment": {"azimuth": {"exact": 0.5}}, "dense": {"mobius": {"mean_error": 0.25}},
                         **{f"count_{j:03d}": j for j in range(150)}}}
            for i in range(3)]
    for head in ({"columns": keys, "better": {}}, None):
        lines = format_table(rows, head).splitlines()
        assert max(len(x) for x in lines) <= columns
        assert max(len(x) for x in lines) > columns - 30          # it uses the room it has
    lines = format_table(rows, {"columns": keys, "better": {}}).splitlines()
    dashes = next(i for i, x in enumerate(lines) if set(x.replace(" ", "")) == {"-"})
    assert dashes == 2                                             # group above measure: more columns fit
    groups, measures = lines[0].split(), lines[1].split()
    assert len(groups) == len(measures) >= 4                       # never a bare "min" or "exact"
    assert (groups[1], measures[1]) == ("seed_stability_0", "min")
    assert ("azimuth", "exact") in set(zip(groups, measures))
    legend = text[text.index("columns:"):] if (text := "\n".join(lines)) else ""
    assert "correspondence.seed_stability_0.min" in legend.replace("\n  ", " ")   # the full keys, wrapped


def test_sweep_plot_leaves_out_trivial_panels_and_is_named_after_the_parameters(tmp_path):
    """A metric that repeats the swept value (times a constant) and a constant are not plotted."""
    rows = [{"point": {"align.sigma_scale": x}, "metrics": {"sigma": 0.04 * float(x), "energy": 7.0,
                                                            "noise": 1.0 + 1e-14 * i, "accuracy": [0.5, 0.7, 0.6][i]}}
            for i, x in enumerate(["0.5", "1", "2"])]
    path = str(tmp_path / "sweeps" / figure_name("demo pipe", ["align.sigma_scale=0.5,1,2"]))
    assert path.endswith("sweeps/demo_pipe_align.sigma_scale=0.5,1,2.png")
    assert plot_sweep(rows, str(tmp_path), os.path.relpath(path, tmp_path)) == path
    import matplotlib.image
    assert matplotlib.image.imread(path).shape[1] <= 3.4 * 100 + 1  # one panel (accuracy), not three
    only_trivial = [{"point": r["point"], "metrics": {"sigma": r["metrics"]["sigma"], "energy": 7.0}} for r in rows]
    assert plot_sweep(only_trivial, str(tmp_path), "none.png") is None


def test_write_table_csv_and_json(tmp_path):
    rows = _rows([0.9, 0.7], [0.1, 0.3])
    with open(write_table(rows, str(tmp_path / "t.csv")), newline="") as fh:
        table = list(csv.reader(fh))
    assert table[0][0] == "sigma" and len(table[0]) == 1 + 2 + 2 + 150 and len(table) == 3
    assert table[1][table[0].index("score.m1")] == "0.9"
    write_table(rows, str(tmp_path / "t.json"))
    assert json.loads((tmp_path / "t.json").read_text())[1]["metrics"]["error"]["m1"] == 0.3


@pytest.fixture
def short_tmp_path():
    """A new folder directly in the system's temporary folder: sweep prints the figure's absolute path, which
    must fit MAX_WIDTH like the table, as it does for a project folder like /home/USER/PROJECT; pytest's
    tmp_path is 60+ characters deep (10 more under pytest-xdist: popen-gwN/)."""
    import shutil
    import tempfile
    from pathlib import Path

    folder = Path(tempfile.mkdtemp(prefix="sweep-"))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def project(short_tmp_path, monkeypatch):
    tmp_path = short_tmp_path
    monkeypatch.chdir(tmp_path)
    with loaded_plugin(tmp_path, monkeypatch, PLUGIN, PLUGIN_SOURCE):
        yield make_project(tmp_path, n=4, yaml_text=SYNTHETIC_YAML + EXTRA)


def test_headline_columns_default_requested_and_unknown(project):
    from stages import api
    plan = api.plan_pipeline(str(project), quiet=True)
    rows = [{"point": {"sigma": "1"}, "metrics": {"score": {"m1": 0.9, "m2": 0.5}, "error": {"m1": 0.1, "m2": 0.4},
                                                  "count_001": 1, "count_002": 2}}]
    head = headline_columns(plan, rows)
    assert head["columns"] == ["score.m1", "error.m1", "score.m2", "error.m2"]     # row by row
    assert head["better"] == {"score.m1": "max", "score.m2": "max", "error.m1": "min", "error.m2": "min"}
    assert headline_columns(plan, rows, ["count_*", "score.m2"])["columns"] == ["count_001", "count_002", "score.m2"]
    with pytest.raises(PipelineError, match="no such metric"):
        headline_columns(plan, rows, ["nope.*"])


def test_sweep_cli_prints_headline_table_and_writes_csv(project, short_tmp_path):
    tmp_path = short_tmp_path   # the project's folder
    env = plugins_env(PLUGIN)
    env["PYTHONPATH"] += ":" + str(tmp_path)
    env["COLUMNS"] = "0"     # unset: the output is a pipe, so the default width
    res = cli_main(["sweep", "p.yaml", "--grid", "sigma=0.5,1,2", "--workers", "0", "--quiet", "--csv", "full.csv"],
              cwd=tmp_path, env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert max(len(x) for x in lines) <= MAX_WIDTH      # no terminal, COLUMNS unset: the default width
    assert lines[0].split() == ["sigma", "score.m1", "error.m1", "score.m2", "error.m2"]
    body = [line.split() for line in lines[2:5]]
    assert [r[0] for r in body] == ["0.5", "1", "2"]
    m1 = [float(r[1].rstrip("*")) for r in body]
    assert [r[1].endswith("*") for r in body] == [v == max(m1) for v in m1]
    with open(tmp_path / "full.csv", newline="") as fh:
        full = list(csv.reader(fh))
    assert len(full) == 4 and "count_149" in full[0] and "per_item.item000.value" not in full[0]  # >12: not flat
    res = cli_main(["sweep", "p.yaml", "--grid", "sigma=0.5,1,2", "--workers", "0", "--quiet", "--metrics",
               "count_00*"], cwd=tmp_path, env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines()[0].split()[:4] == ["sigma", "count_000", "count_001", "count_002"]
    res = cli_main(["sweep", "p.yaml", "--grid", "sigma=0.5,1,2", "--workers", "0", "--quiet"], cwd=tmp_path,
              env={**env, "COLUMNS": "80"}, timeout=300)
    table = [x for x in res.stdout.splitlines() if not x.startswith("figure: ")]   # (a path: not wrapped)
    assert table and max(len(x) for x in table) <= 80


def test_progress_estimates_time_left():
    stream = io.StringIO()
    p = Progress({"s": 11}, stream=stream)
    p.update("s", True)
    assert p.eta("s") == ""                      # one task done: no rate yet
    start = p.first_done["s"]
    p.done["s"] = 6                               # 5 more tasks in 10 s after the first: 2 s each, 5 left
    assert p.eta("s", now=start + 10) == ", ~10s left"
    p.done["s"] = 2
    assert p.eta("s", now=start + 100) == ", ~15.0 min left"
    p.done["s"] = 11
    assert p.eta("s", now=start + 100) == ""      # finished
