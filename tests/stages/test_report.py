"""The HTML report: run a small pipeline (with align./corr. plugin stages that publish PNG/SVG figures), a sweep,
then parse the report with html.parser and check figures, metrics, sweeps and provenance against the engine's
own records."""
from __future__ import annotations

from pathlib import Path

import base64
import math
import os
import sys
from html.parser import HTMLParser

import numpy as np
import pytest

from tests.helpers import SYNTHETIC_YAML, cli, cli_main, loaded_plugin, make_project, plugins_env
from stages import api
from stages.report import render_value, write_report
from stages.report.context import stage_seconds

PLUGIN = "report_test_plugin"

PLUGIN_SOURCE = '''
"""Stage functions for tests/test_report.py: figures for both problems and nested metrics."""
import os
import struct
import zlib

import numpy as np

from stages.registry import Headline, Measure, Plugin, register

PLUGIN = Plugin(name="report_test", packages=(__name__,), report_packages=("pytest",),
                groups={"problem1": "Problem 1: alignment-like", "problem2": "Problem 2: correspondence-like"},
                headlines=(Headline(group="problem2", title="Matching per method", rows_from="accuracy",
                                    measures=(Measure("top 1", "accuracy.{row}.top1"),
                                              Measure("top 5", "accuracy.{row}.top5"),
                                              Measure("pairs", "n_pairs", better=None, only_row="best_method"),
                                              Measure("seconds per task", "@seconds_per_task", better="min")),
                                    row_inputs={"mrf": "summary", "nearest": "summary"},
                                    figures=("align.rtest_figures:overview.png", "nothing.here:missing.png")),
                           Headline(group="problem1", title="Empty: no such metric",
                                    measures=(Measure("x", "no.such.{row}"),), rows=("a", "b"))))


def tiny_png(w, h, rgb):
    """A valid w x h RGB PNG of one colour (stdlib only)."""
    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)
    raw = b"".join(b"\\x00" + bytes(rgb) * w for _ in range(h))
    return (b"\\x89PNG\\r\\n\\x1a\\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


@register("align.rtest_figures", group="problem1", fanout="once", writes_files=True)
def align_figures(summary, *, out_dir):
    """Alignment-like figures: an overview with a caption file, a nested figure and a CSV."""
    with open(os.path.join(out_dir, "overview.png"), "wb") as fh:
        fh.write(tiny_png(6, 4, (200, 10, 10)))
    with open(os.path.join(out_dir, "overview.txt"), "w") as fh:
        fh.write("Aligned collection, n=%d" % summary["n_items"])
    os.makedirs(os.path.join(out_dir, "poses"))
    with open(os.path.join(out_dir, "poses", "pose_a.png"), "wb") as fh:
        fh.write(tiny_png(3, 3, (10, 200, 10)))
    with open(os.path.join(out_dir, "angles.csv"), "w") as fh:
        fh.write("item,angle\\n" + "".join("s%03d,%d\\n" % (i, 15 * i) for i in range(summary["n_items"])))
    return {"files": 4}


@register("corr.rtest_figures", group="problem2", fanout="item", writes_files=True)
def corr_figures(features, *, out_dir):
    """Per-item correspondence figure (PNG whose colour depends on the item) and an SVG."""
    c = int(abs(float(np.asarray(features).sum())) * 1000) % 256
    with open(os.path.join(out_dir, "matches.png"), "wb") as fh:
        fh.write(tiny_png(2, 5, (c, 0, 255 - c)))
    with open(os.path.join(out_dir, "matches.svg"), "w") as fh:
        fh.write('<svg xmlns="http://www.w3.org/2000/svg" width="4" height="4"><rect width="4" height="%d"/></svg>'
                 % (c % 4 + 1))
    return c


@register("corr.rtest_accuracy", group="problem2", fanout="once")
def corr_accuracy(summary, *, top: int = 5):
    """Nested metrics: accuracy per method, a 100-entry labels dict and an array."""
    a = summary["mean_affinity"]
    return {"accuracy": {"mrf": {"top1": round(a, 4), "top%d" % top: 0.95},
                         "nearest": {"top1": 0.5, "top%d" % top: 0.75}},
            "labels": {"v%03d" % i: i % 7 for i in range(100)}, "best_method": "mrf",
            "n_pairs": summary["n_items"] ** 2, "per_item_error": np.linspace(0.0, 1.0, 50)}
'''

EXTRA_STAGES = """\
  align_figs:
    function: align.rtest_figures
    inputs: {summary: summary}
  corr_figs:
    function: corr.rtest_figures
    foreach: feat
    inputs: {features: feat}
  corr_eval:
    function: corr.rtest_accuracy
    inputs: {summary: summary}
    metrics: true
"""


class ReportParser(HTMLParser):
    """Collects images (with the section they are in), every src/href, tables (rows of cell texts, by class),
    <details> summaries and the plain text."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.images: list[dict] = []
        self.links: list[str] = []
        self.tables: list[dict] = []
        self.section: str | None = None
        self.section_ids: list[str] = []
        self.text: list[str] = []
        self._stack: list[dict] = []      # open tables (nested tables are separate entries)
        self._cell: list[str] | None = None
        self._details_depth = 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for k in ("src", "href"):
            if k in a:
                self.links.append(a[k])
        if tag == "section":
            self.section = a.get("id")
            self.section_ids.append(self.section)
        elif tag == "img":
            self.images.append({"src": a.get("src", ""), "section": self.section, "title": a.get("title")})
        elif tag == "details":
            self._details_depth += 1
        elif tag == "table":
            t = {"cls": a.get("class", ""), "rows": [], "section": self.section, "folded": self._details_depth > 0}
            self.tables.append(t)
            self._stack.append(t)
        elif tag == "tr" and self._stack:
            self._stack[-1]["rows"].append([])
        elif tag in ("td", "th") and self._stack:
            self._cell = []

    def handle_endtag(self, tag):
        if tag == "table" and self._stack:
            self._stack.pop()
        elif tag in ("td", "th") and self._stack and self._cell is not None:
            self._stack[-1]["rows"][-1].append("".join(self._cell).strip())
            self._cell = None
        elif tag == "details":
            self._details_depth -= 1
        elif tag == "section":
            self.section = None

    def handle_data(self, data):
        self.text.append(data)
        if self._cell is not None:
            self._cell.append(data)


def parse(path: str) -> ReportParser:
    p = ReportParser()
    with open(path, encoding="utf-8") as fh:
        p.feed(fh.read())
    p.close()
    return p


def _matches(cell: str, value) -> bool:
    if isinstance(value, bool) or isinstance(value, str):
        return cell == str(value)
    try:
        return math.isclose(float(cell), float(value), rel_tol=1e-5, abs_tol=1e-12)
    except ValueError:
        return False


def _has_row(tables: list[dict], *cells) -> bool:
    """Some table row starts with these cells (strings exactly, numbers approximately)."""
    return any(len(r) >= len(cells) and all(_matches(c, v) for c, v in zip(r, cells))
               for t in tables for r in t["rows"])


@pytest.fixture
def project(tmp_path, monkeypatch):
    """The synthetic pipeline plus align./corr. plugin stages, in tmp_path (the cwd)."""
    monkeypatch.chdir(tmp_path)
    with loaded_plugin(tmp_path, monkeypatch, PLUGIN, PLUGIN_SOURCE):
        yield make_project(tmp_path, n=6, yaml_text=SYNTHETIC_YAML + EXTRA_STAGES)


def test_report_contents(project, tmp_path):
    path = str(project)
    api.run(path, workers=0, quiet=True)
    summary = api.run(path, ["rep.title=second"], workers=0, quiet=True)   # only 'rep' executes
    sweep = api.sweep(path, ["sigma=0.5,1"], workers=0, quiet=True)
    out_dir = tmp_path / "results" / "syn"
    # a figure not written by any stage (e.g. a sweep plot) is reported too
    import report_test_plugin as plug
    (out_dir / "sweep_sigma.png").write_bytes(plug.tiny_png(5, 5, (1, 2, 3)))

    report = write_report(path, ["rep.title=second"])
    assert report == str(out_dir / "report.html")
    doc = parse(report)

    # every image under the output folder is embedded byte-for-byte, in the right section
    images = sorted(p for p in out_dir.rglob("*") if p.suffix in (".png", ".svg"))
    # 2 stage figures + 2 per item for 6 items + the extra one + the sweep's own plot of metric vs sigma
    assert len(images) == 1 + 2 + 2 * 6 + 1
    assert sweep["figure"] and Path(sweep["figure"]).is_file()
    by_title = {im["title"]: im for im in doc.images}
    assert len(doc.images) == len(images)
    for p in images:
        rel = p.relative_to(out_dir).as_posix()
        im = by_title[rel]
        mime = "image/png" if p.suffix == ".png" else "image/svg+xml"
        prefix = f"data:{mime};base64,"
        assert im["src"].startswith(prefix), rel
        assert base64.b64decode(im["src"][len(prefix):]) == p.read_bytes(), rel
        expected_section = {"align_figs": "problem1", "corr_figs": "problem2",
                            "sweeps": "sweeps"}.get(rel.split("/")[0], "figures")
        if rel == "align_figs/overview.png":
            expected_section = "summary"     # a headline figure: embedded in the summary, pointed to in problem1
        assert im["section"] == expected_section, rel
    text = "".join(doc.text)
    assert "Aligned collection, n=6" in text                       # the caption file
    assert "align_figs/angles.csv" in text                          # other files are listed ...
    assert "align_figs/overview.txt" not in text                   # ... but not caption files

    # sections and table of contents
    for sid in ("summary", "problem1", "problem2", "figures", "metrics", "sweeps", "provenance"):
        assert sid in doc.section_ids
        assert f"#{sid}" in doc.links
    # nothing external: the only links out of the page are the figures' own files (each opens full size), by
    # paths relative to the report, so the output folder can be moved or archived as a whole
    files = [x for x in doc.links if not x.startswith(("data:", "#"))]
    assert sorted(files) == sorted(p.relative_to(out_dir).as_posix() for p in images)

    # every scalar metric, by dotted name and value, in the headline table
    plan = api.plan_pipeline(path, ["rep.title=second"], quiet=True)
    m = api.metrics(plan)
    flat = api.scalar_metrics(m)
    assert {"n_items", "mean_affinity", "sigma", "n_pairs", "accuracy.mrf.top1", "accuracy.nearest.top5"} <= set(flat)
    headline = [t for t in doc.tables if t["cls"] == "scalar-metrics"]
    for k, v in flat.items():
        assert _has_row(headline, k, v), k
    assert flat["n_pairs"] == 36
    # nested metrics: accuracy as a method x measure matrix; labels folded (100 rows); array summarised
    metric_tables = [t for t in doc.tables if t["section"] == "metrics"]
    assert _has_row(metric_tables, "", "top1", "top5")
    assert _has_row(metric_tables, "mrf", m["accuracy"]["mrf"]["top1"], 0.95)
    assert _has_row(metric_tables, "nearest", 0.5, 0.75)
    labels = [t for t in metric_tables if t["folded"] and len(t["rows"]) == 101]
    assert labels and _has_row(labels, "v042", 0)
    assert "shape (50,)" in text and "max 1" in text

    # the sweep: one row per grid point with its metrics
    sweeps = [t for t in doc.tables if t["cls"] == "sweep"]
    assert len(sweeps) == 1
    header, *rows = sweeps[0]["rows"]      # the headline measures only (the declared headline's cells)
    assert header[0] == "sigma" and "accuracy.mrf.top1" in header and "mean_affinity" not in header
    col = header.index("accuracy.mrf.top1")
    assert len(rows) == len(sweep["rows"]) == 2
    star = "\u2605\u00a0"
    values = [point["metrics"]["accuracy"]["mrf"]["top1"] for point in sweep["rows"]]
    for r, point, v in zip(rows, sweep["rows"], values):
        assert r[0] == point["point"]["sigma"]
        assert _matches(r[col].replace(star, ""), v)
        assert r[col].startswith(star) == (v == max(values))      # the best of the column is starred
    assert values[0] != values[1]
    [full] = [t for t in doc.tables if t["cls"] == "sweep-full"]  # every scalar metric, folded
    assert full["folded"] and "mean_affinity" in full["rows"][0]
    fcol = full["rows"][0].index("mean_affinity")
    for r, point in zip(full["rows"][1:], sweep["rows"]):
        assert _matches(r[fcol], point["metrics"]["mean_affinity"])
    assert not math.isclose(float(full["rows"][1][fcol]), float(full["rows"][2][fcol]))

    # provenance: executed / cached per stage of the last run (only 'rep' was re-executed)
    prov = [t for t in doc.tables if t["cls"] == "provenance"][0]
    head = prov["rows"][0]
    ex, ca = head.index("executed (last run)"), head.index("cached (last run)")
    got = {r[0]: (int(r[ex]), int(r[ca])) for r in prov["rows"][1:]}
    assert got == {name: (s["executed"], s["cached"]) for name, s in summary["stages"].items()}
    assert got["rep"] == (1, 0) and got["feat"] == (0, 6) and got["corr_figs"] == (0, 6)
    for name, sp in plan.stages.items():
        assert sp.code[:12] in [r[head.index("code fingerprint")] for r in prov["rows"][1:] if r[0] == name]
    versions = [t for t in doc.tables if t["cls"] == "versions"][0]
    assert _has_row([versions], "numpy", np.__version__)
    assert _has_row([versions], "python", ".".join(map(str, sys.version_info[:3])))
    names = {r[0] for r in versions["rows"]}
    assert {"dask", "distributed", "zarr", "pyyaml", "pytest"} <= names   # the engine's + what the plugin declares
    assert "open3d" not in names            # declared by the shapecorr plugin, whose functions this pipeline does not use


def test_report_before_any_run_and_cli(project, tmp_path):
    path = str(project)
    first = parse(write_report(path))
    text = " ".join(first.text)
    assert "Nothing has been run yet" in text and "python -m stages run " + path in text
    assert first.images == []

    api.run(path, workers=0, quiet=True)
    env = plugins_env(PLUGIN)
    env["PYTHONPATH"] += os.pathsep + str(tmp_path)
    res = cli_main(["report", "p.yaml", "--out", "r.html"], cwd=tmp_path, env=env, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == str(tmp_path / "r.html")
    doc = parse(str(tmp_path / "r.html"))
    assert len(doc.images) == 2 + 2 * 6          # align: 2 PNG; corr: PNG + SVG per item; earlier report ignored
    assert "Nothing has been run yet" not in "".join(doc.text)
    files = [x for x in doc.links if not x.startswith(("data:", "#"))]     # --out elsewhere: links still resolve
    assert len(files) == len(doc.images) and all((tmp_path / f).is_file() for f in files)


def test_render_value_folds_big_structures():
    small = render_value({"a": 1, "b": 2.5})
    assert "<details" not in small and "2.5" in small
    big = render_value({f"k{i}": i for i in range(100)})
    assert big.startswith("<details") and "100 entries" in big and big.count("<tr>") == 101
    assert "&lt;script&gt;" in render_value({"x": "<script>"})
    arr = render_value(np.arange(1000.0).reshape(10, 100))
    assert "shape (10, 100)" in arr and "max 999" in arr and "<table" not in arr


def test_report_summary_first(project, tmp_path):
    """The summary holds the declared headline tables (best value starred per column, measures limited to
    their row), their figures (each image embedded once: a pointer in the stage's section), and few table
    rows come before the first figure; a headline without any value is left out."""
    path = str(project)
    api.run(path, workers=0, quiet=True)
    html_path = write_report(path)
    doc = parse(html_path)
    plan = api.plan_pipeline(path, quiet=True)
    m = api.metrics(plan)
    [t] = [t for t in doc.tables if t["cls"] == "summary-table"]
    assert t["section"] == "summary" and not t["folded"]
    header, *rows = t["rows"]
    assert header == ["method", "top 1", "top 5", "pairs", "seconds per task"]
    by_row = {r[0]: r[1:] for r in rows}
    assert list(by_row) == ["mrf", "nearest"]
    star = "\u2605"
    top1 = {"mrf": m["accuracy"]["mrf"]["top1"], "nearest": 0.5}
    best1 = max(top1, key=top1.get)
    assert by_row[best1][0].startswith(star) and not by_row[min(top1, key=top1.get)][0].startswith(star)
    assert by_row["mrf"][1] == f"{star}\u00a00.95" and by_row["nearest"][1] == "0.75"
    assert by_row["mrf"][2] == "36" and by_row["nearest"][2] == "\u2013"      # only_row: the named row only
    seconds = stage_seconds(plan)["summary"]        # one task
    assert seconds is not None and float(by_row["mrf"][3].lstrip(star + "\u00a0")) == pytest.approx(
        seconds, rel=2e-2, abs=1e-4)
    text = "".join(doc.text)
    assert "Empty: no such metric" not in text
    overview = [im for im in doc.images if im["title"] == "align_figs/overview.png"]
    assert len(overview) == 1 and overview[0]["section"] == "summary"
    assert "shown in" in text
    raw = Path(html_path).read_text(encoding="utf-8")
    assert raw[:raw.index("<img")].count("<tr") <= 40
    assert "tasks ran" in text or "task(s) ran" in text


def test_best_indices_and_headline_marks():
    from stages.headline import best_indices
    assert best_indices([0.5, None, 0.9, 0.9], "max") == {2, 3}
    assert best_indices([0.5, 0.2, float("nan")], "min") == {1}
    assert best_indices([0.5, 0.2], None) == set()
    assert best_indices([0.5, None], "max") == set()          # one value: nothing to compare
    assert best_indices([1.0, 1.0, 1.0], "max") == set()      # all equal: nothing to mark


def test_report_results_folder_option(project, tmp_path):
    """``report --results DIR`` shows the figures published to DIR (what ``run --out DIR`` was given)."""
    import shutil
    path = str(project)
    api.run(path, workers=0, quiet=True)
    shutil.move(str(tmp_path / "results" / "syn"), str(tmp_path / "elsewhere"))
    env = plugins_env(PLUGIN)
    env["PYTHONPATH"] += os.pathsep + str(tmp_path)
    res = cli_main(["report", "p.yaml", "--out", "r.html"], cwd=tmp_path, env=env, timeout=120)
    assert res.returncode == 0, res.stderr
    assert parse(str(tmp_path / "r.html")).images == []            # the pipeline's own output folder is empty
    res = cli_main(["report", "p.yaml", "--results", "elsewhere"], cwd=tmp_path, env=env, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == str(tmp_path / "elsewhere" / "report.html")
    assert len(parse(res.stdout.strip()).images) == 2 + 2 * 6
