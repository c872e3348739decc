"""One self-contained HTML report of a pipeline: figures, metrics, sweeps and provenance.

``write_report("pipeline.yaml")`` reads only what the engine already stored (the cache, the last run record,
the recorded sweeps and the published output folder); it runs no stage. Images are embedded as base64 data
URIs and the CSS is inline, so the file can be mailed or archived on its own.
"""
from __future__ import annotations

import base64
import datetime as _dt
import glob
import hashlib
import html
import importlib.metadata
import json
import math
import os
import platform
import re
import subprocess
import sys
from typing import Any, Iterable

import numpy as np

from .record import load_record, pipeline_id
from .runner import metrics as pipeline_metrics, plan_pipeline, scalar_metrics
from .store import atomic_write_text

PACKAGES = ("numpy", "scipy", "dask", "distributed", "zarr", "open3d", "scikit-image", "potpourri3d",
            "robust_laplacian", "matplotlib", "pyyaml")
IMAGE_TYPES = {".png": "image/png", ".svg": "image/svg+xml"}
PROBLEMS = (("align.", "problem1", "Problem 1: alignment"), ("corr.", "problem2", "Problem 2: correspondence"))
MAX_INLINE_ENTRIES = 12      # dicts/lists longer than this are folded into a <details> element
MAX_ROWS_SHOWN = 2000        # rows of a folded table actually written

CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:0 auto;max-width:1200px;padding:1em 2em;
color:#222;line-height:1.4}
h1{border-bottom:2px solid #446;padding-bottom:.2em}h2{border-bottom:1px solid #aab;margin-top:2em}
h3{margin-top:1.5em}code,pre{font-family:Menlo,Consolas,monospace;font-size:.9em}
pre{background:#f5f5f8;padding:.6em;overflow-x:auto;max-height:30em}
table{border-collapse:collapse;margin:.5em 0 1em 0;font-size:.92em}
th,td{border:1px solid #ccd;padding:.2em .6em;text-align:left;vertical-align:top}
th{background:#eef}td.num{text-align:right;font-variant-numeric:tabular-nums}
tr:nth-child(even) td{background:#fafafd}
.note{background:#fff8e0;border-left:4px solid #e0b000;padding:.5em 1em;margin:1em 0}
.bad{color:#b00}.muted{color:#777}
.figs{display:flex;flex-wrap:wrap;gap:1em}
figure{margin:0;border:1px solid #dde;padding:.5em;max-width:100%;background:#fff}
figure img{max-width:100%;max-height:720px;display:block}
figcaption{font-size:.9em;margin-top:.3em}figcaption pre{max-height:12em;margin:.3em 0 0 0}
details{margin:.3em 0 1em 0}summary{cursor:pointer;color:#335}
nav ul{columns:2}
"""


# ---------------------------------------------------------------------------------------------
# small HTML helpers
# ---------------------------------------------------------------------------------------------
def esc(value: Any) -> str:
    return html.escape(str(value), quote=True)


def format_value(v: Any) -> str:
    """Text of a scalar cell: floats with 6 significant digits, the rest as str."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float):
        return f"{v:.6g}" if math.isfinite(v) else str(v)
    return str(v)


def _is_scalar(v: Any) -> bool:
    return v is None or isinstance(v, (bool, int, float, str, np.generic)) or \
        (isinstance(v, np.ndarray) and v.ndim == 0)


def _cell(v: Any) -> str:
    if isinstance(v, np.ndarray) and v.ndim == 0:
        v = v.item()
    numeric = isinstance(v, (int, float, np.number)) and not isinstance(v, bool)
    return f'<td class="num">{esc(format_value(v))}</td>' if numeric else f"<td>{esc(format_value(v))}</td>"


def table(header: list[str], rows: Iterable[list[Any]], cls: str = "", raw_cols: tuple[int, ...] = ()) -> str:
    """An HTML table; cells are escaped scalars, except columns in ``raw_cols`` (already HTML)."""
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    body = []
    for r in rows:
        cells = "".join(f"<td>{c}</td>" if i in raw_cols else _cell(c) for i, c in enumerate(r))
        body.append(f"<tr>{cells}</tr>")
    attr = f' class="{cls}"' if cls else ""
    return f"<table{attr}><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _folded(summary: str, inner: str, open_: bool = False) -> str:
    return f"<details{' open' if open_ else ''}><summary>{esc(summary)}</summary>{inner}</details>"


def _anchor(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "x"


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return str(n)


def _json_pre(obj: Any) -> str:
    return f"<pre>{esc(json.dumps(obj, indent=2, sort_keys=False, default=str))}</pre>"


# ---------------------------------------------------------------------------------------------
# rendering a metric value tree
# ---------------------------------------------------------------------------------------------
def render_value(v: Any) -> str:
    """HTML for a metric value: scalars as text, dicts as tables (nested or matrix), big ones folded."""
    if _is_scalar(v):
        return esc(format_value(v.item() if isinstance(v, np.ndarray) else v))
    if isinstance(v, np.ndarray):
        return _render_array(v)
    if isinstance(v, (list, tuple)):
        return _render_list(list(v))
    if isinstance(v, dict):
        return _render_dict(v)
    return esc(repr(v))


def _render_array(a: np.ndarray) -> str:
    desc = f"array {a.dtype} shape {tuple(a.shape)}"
    if a.size <= MAX_INLINE_ENTRIES and a.ndim == 1:
        return esc(", ".join(format_value(x) for x in a.tolist())) + f' <span class="muted">({esc(desc)})</span>'
    if a.size and np.issubdtype(a.dtype, np.number):
        finite = a[np.isfinite(a)] if np.issubdtype(a.dtype, np.floating) else a
        if finite.size:
            desc += (f": min {format_value(float(finite.min()))}, mean {format_value(float(finite.mean()))}, "
                     f"max {format_value(float(finite.max()))}")
    if a.ndim == 2 and a.size <= 400:
        return _folded(desc, table([""] + [str(j) for j in range(a.shape[1])],
                                   [[i] + row for i, row in enumerate(a.tolist())]))
    return esc(desc)


def _render_list(v: list) -> str:
    if all(_is_scalar(x) for x in v):
        text = ", ".join(format_value(x) for x in v)
        if len(v) <= MAX_INLINE_ENTRIES and len(text) <= 200:
            return esc(text) if v else '<span class="muted">(empty)</span>'
        rows = [[i, x] for i, x in enumerate(v[:MAX_ROWS_SHOWN])]
        return _folded(f"list of {len(v)} values", table(["#", "value"], rows) + _more(len(v)))
    rows = [[i, render_value(x)] for i, x in enumerate(v[:MAX_ROWS_SHOWN])]
    inner = table(["#", "value"], rows, raw_cols=(1,)) + _more(len(v))
    return inner if len(v) <= MAX_INLINE_ENTRIES else _folded(f"list of {len(v)} entries", inner)


def _more(n: int) -> str:
    return f'<p class="muted">... {n - MAX_ROWS_SHOWN} more not shown</p>' if n > MAX_ROWS_SHOWN else ""


def _render_dict(d: dict) -> str:
    items = list(d.items())
    if not items:
        return '<span class="muted">(empty)</span>'
    if all(_is_scalar(x) for _, x in items):
        inner = table(["key", "value"], [[k, x] for k, x in items[:MAX_ROWS_SHOWN]]) + _more(len(items))
    elif all(isinstance(x, dict) and x and all(_is_scalar(y) for y in x.values()) for _, x in items):
        cols = list(dict.fromkeys(c for _, x in items for c in x))
        if len(cols) <= 16:     # a matrix: rows = outer keys, columns = inner keys
            rows = [[k] + [x.get(c, "") for c in cols] for k, x in items[:MAX_ROWS_SHOWN]]
            inner = table([""] + cols, rows) + _more(len(items))
        else:
            inner = table(["key", "value"], [[k, _render_dict(x)] for k, x in items[:MAX_ROWS_SHOWN]],
                          raw_cols=(1,)) + _more(len(items))
    else:
        inner = table(["key", "value"], [[k, render_value(x)] for k, x in items[:MAX_ROWS_SHOWN]],
                      raw_cols=(1,)) + _more(len(items))
    return inner if len(items) <= MAX_INLINE_ENTRIES else _folded(f"{len(items)} entries", inner)


# ---------------------------------------------------------------------------------------------
# gathering
# ---------------------------------------------------------------------------------------------
def problem_of(function: str) -> str | None:
    """"problem1" for align.* functions, "problem2" for corr.*, else None."""
    for prefix, key, _ in PROBLEMS:
        if function.startswith(prefix):
            return key
    return None


def published_files(output_dir: str, exclude: Iterable[str] = ()) -> list[str]:
    """Relative paths (with '/') of every file under ``output_dir``, sorted; ``exclude``: absolute paths."""
    skip = {os.path.abspath(p) for p in exclude}
    out = []
    for dirpath, dirnames, files in os.walk(output_dir):
        dirnames.sort()
        for f in files:
            full = os.path.abspath(os.path.join(dirpath, f))
            if full not in skip and not f.endswith(".tmp"):
                out.append(os.path.relpath(full, output_dir).replace(os.sep, "/"))
    return sorted(out)


def _data_uri(path: str) -> str:
    mime = IMAGE_TYPES[os.path.splitext(path)[1].lower()]
    with open(path, "rb") as fh:
        return f"data:{mime};base64,{base64.b64encode(fh.read()).decode('ascii')}"


def _caption_file(rel: str) -> str:
    return os.path.splitext(rel)[0] + ".txt"


def _stage_seconds(plan) -> dict[str, float | None]:
    """Per stage: the summed compute seconds of its stored tasks (from the manifests), None if none stored."""
    out: dict[str, float | None] = {}
    for name, sp in plan.stages.items():
        secs = [(plan.store.manifest(t.key) or {}).get("info", {}).get("seconds") for t in sp.tasks
                if plan.store.has(t.key)]
        secs = [s for s in secs if isinstance(s, (int, float))]
        out[name] = round(sum(secs), 4) if secs else None
    return out


def _metric_origins(plan) -> dict[str, str]:
    """Top-level metric key -> the metrics stage whose result holds it (read from the manifests)."""
    origin = {}
    for name, sp in plan.stages.items():
        if not sp.spec.metrics:
            continue
        for t in sp.tasks:
            tree = (plan.store.manifest(t.key) or {}).get("tree")
            if isinstance(tree, dict) and "__dict__" in tree:
                for k in tree["__dict__"]:
                    origin[k] = name
            elif tree is not None:
                origin[name] = name
    return origin


def load_sweeps(plan) -> list[dict]:
    """The recorded sweeps of this pipeline file, oldest first (each with its file name under "_file")."""
    pattern = os.path.join(plan.store.root, "sweeps", glob.escape(pipeline_id(plan)) + "-*.json")
    out = []
    for path in glob.glob(pattern):
        try:
            with open(path, encoding="utf-8") as fh:
                sw = json.load(fh)
        except (OSError, json.JSONDecodeError):
            continue
        sw["_file"] = path
        out.append(sw)
    return sorted(out, key=lambda s: s.get("time", 0))


def package_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def _git_commit(folder: str) -> str | None:
    try:
        res = subprocess.run(["git", "rev-parse", "HEAD"], cwd=folder, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return res.stdout.strip() if res.returncode == 0 else None


def _when(t: float | None) -> str:
    if not t:
        return "?"
    return _dt.datetime.fromtimestamp(t, _dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")


# ---------------------------------------------------------------------------------------------
# sections
# ---------------------------------------------------------------------------------------------
def _summary_section(ctx: dict) -> str:
    plan, record, m = ctx["plan"], ctx["record"], ctx["metrics"]
    parts = []
    cmd = f"python -m stages run {ctx['pipeline_arg']}" + "".join(f" --set {o}" for o in ctx["overrides"])
    if ctx["nothing_run"]:
        parts.append(f'<p class="note"><b>Nothing has been run yet</b> for this configuration: no result is in '
                     f"the cache <code>{esc(plan.store.root)}</code>. Run <code>{esc(cmd)}</code> and then "
                     f"<code>python -m stages report {esc(ctx['pipeline_arg'])}</code> again.</p>")
    elif ctx["incomplete"]:
        parts.append(f'<p class="note">Not every task of this configuration is in the cache '
                     f"({ctx['stored']} of {ctx['total']} stored). To complete it run <code>{esc(cmd)}</code>.</p>")
    if record and ctx["record_differs"]:
        parts.append('<p class="note">The last recorded run of this pipeline file used a different configuration '
                     f"(overrides: <code>{esc(' '.join(record.get('overrides') or []) or '(none)')}</code>) "
                     "than this report (overrides: "
                     f"<code>{esc(' '.join(ctx['overrides']) or '(none)')}</code>). Published figures and files come "
                     "from that last run; metrics and cache counts below are for this configuration.</p>")
    rows = [["pipeline", plan.pipeline.name], ["file", plan.pipeline.file],
            ["overrides", " ".join(ctx["overrides"]) or "(none)"], ["output folder", plan.pipeline.output_dir],
            ["cache", plan.store.root], ["results in cache", f"{ctx['stored']} of {ctx['total']} tasks"]]
    if record:
        summ = record.get("summary") or {}
        rows += [["last run", _when(record.get("time"))], ["last run wall time (s)", summ.get("wall_seconds", "?")]]
    rows.append(["report written", _when(ctx["now"])])
    parts.append(table(["", ""], rows))
    head = scalar_metrics(m)
    if head:
        parts.append("<h3>Headline metrics</h3>")
        parts.append(table(["metric", "value"], [[k, v] for k, v in head.items()], cls="headline"))
    if "_not_computed" in m:
        parts.append(f'<p class="bad">Metrics not computed yet: {esc(", ".join(m["_not_computed"]))}.</p>')
    return "".join(parts)


def _figure_html(ctx: dict, rel: str) -> str:
    out_dir = ctx["plan"].pipeline.output_dir
    caption = f"<code>{esc(rel)}</code>"
    cap_rel = _caption_file(rel)
    if cap_rel in ctx["caption_files"]:
        with open(os.path.join(out_dir, cap_rel), encoding="utf-8", errors="replace") as fh:
            caption += f"<pre>{esc(fh.read().strip())}</pre>"
    title = os.path.splitext(rel.split("/", 1)[-1])[0].replace("_", " ")   # path inside the stage folder
    return (f'<figure><img src="{_data_uri(os.path.join(out_dir, rel))}" alt="{esc(title)}" title="{esc(rel)}">'
            f"<figcaption><b>{esc(title)}</b> {caption}</figcaption></figure>")


def _figures_block(ctx: dict, stage_names: list[str], extra_groups: list[str] = ()) -> str:
    """The figures of the given stages (and of other top-level folders), one subsection each."""
    plan, parts = ctx["plan"], []
    for group in list(stage_names) + list(extra_groups):
        figs = ctx["figures_by_group"].get(group, [])
        if not figs:
            continue
        if group in plan.stages:
            sp = plan.stages[group]
            fanout = {"item": "per item", "pair": "per pair tile"}.get(sp.spec.fanout, "once")
            label = f"{group} ({sp.spec.function}, {fanout})"
        else:
            label = "pipeline folder (sweep and summary figures)" if group == "" else f"{group} (not a stage)"
        parts.append(f'<h3 id="fig-{_anchor(group or "top")}">{esc(label)}: {len(figs)} figure(s)</h3>')
        blocks = "".join(_figure_html(ctx, rel) for rel in figs)
        grid = f'<div class="figs">{blocks}</div>'
        parts.append(grid if len(figs) <= 24 else _folded(f"{len(figs)} figures", grid, open_=True))
    return "".join(parts)


def _files_section(ctx: dict) -> str:
    others = ctx["other_files"]
    if not others:
        return ""
    out_dir = ctx["plan"].pipeline.output_dir
    rows = []
    for rel in others:
        try:
            size = os.path.getsize(os.path.join(out_dir, rel))
        except OSError:
            size = 0
        rows.append([rel, _size(size)])
    inner = table(["file (relative to the output folder)", "size"], rows)
    return (f"<h3>Other published files</h3><p>Under <code>{esc(out_dir)}</code> (not embedded).</p>"
            + (inner if len(rows) <= 40 else _folded(f"{len(rows)} files", inner)))


def _metrics_section(ctx: dict) -> str:
    plan, m = ctx["plan"], ctx["metrics"]
    shown = {k: v for k, v in m.items() if not k.startswith("_")}
    if not shown:
        return "<p>No metrics computed yet" + (
            " (no stage of this pipeline is marked <code>metrics: true</code>)." if not any(
                sp.spec.metrics for sp in plan.stages.values()) else ".") + "</p>"
    origin = ctx["metric_origin"]
    by_stage: dict[str, list[str]] = {}
    for k in shown:
        by_stage.setdefault(origin.get(k, "?"), []).append(k)
    parts = []
    for stage, keys in by_stage.items():
        sp = plan.stages.get(stage)
        label = f"{stage} ({sp.spec.function})" if sp else "metrics"
        parts.append(f"<h3>{esc(label)}</h3>")
        scalars = [[k, shown[k]] for k in keys if _is_scalar(shown[k])]
        if scalars:
            parts.append(table(["metric", "value"], scalars))
        for k in keys:
            if not _is_scalar(shown[k]):
                parts.append(f"<h4>{esc(k)}</h4>{render_value(shown[k])}")
    return "".join(parts)


def _sweeps_section(ctx: dict) -> str:
    sweeps = ctx["sweeps"]
    if not sweeps:
        return (f"<p>No sweep recorded for this pipeline file. Run e.g. <code>python -m stages sweep "
                f"{esc(ctx['pipeline_arg'])} --grid KEY=V1,V2</code>.</p>")
    parts = []
    for i, sw in enumerate(sweeps, 1):
        rows = sw.get("rows", [])
        grid = " ".join(f"--grid {g}" for g in sw.get("grid", []))
        parts.append(f"<h3>Sweep {i}: <code>{esc(grid)}</code></h3>")
        parts.append(f"<p>{len(rows)} point(s), run {esc(_when(sw.get('time')))}"
                     + (f", fixed overrides <code>{esc(' '.join(sw['overrides']))}</code>" if sw.get("overrides")
                        else "") + ".</p>")
        point_cols = list(dict.fromkeys(k for r in rows for k in r.get("point", {})))
        flat = [scalar_metrics(r.get("metrics") or {}) for r in rows]
        metric_cols = list(dict.fromkeys(k for f in flat for k in f))
        body = []
        for r, f in zip(rows, flat):
            missing = (r.get("metrics") or {}).get("_not_computed")
            body.append([r["point"].get(c, "") for c in point_cols] + [f.get(c, "") for c in metric_cols]
                        + ([", ".join(missing)] if missing else [""]))
        header = point_cols + [f"{c} (metric)" if c in point_cols else c for c in metric_cols] + ["not computed"]
        parts.append(table(header, body, cls="sweep"))
        if sw.get("failures"):
            parts.append(f'<p class="bad">{len(sw["failures"])} task(s) failed:</p>'
                         + table(["stage", "item", "error"],
                                 [[f.get("stage"), f.get("item"), f.get("error")] for f in sw["failures"][:50]]))
    return "".join(parts)


def _provenance_section(ctx: dict) -> str:
    plan, record = ctx["plan"], ctx["record"]
    last = (record or {}).get("summary", {}).get("stages", {})
    rec_stages = (record or {}).get("stages", {})
    parts = ["<h3>Stages</h3>"]
    if not record:
        parts.append('<p class="muted">No run recorded yet: executed / cached counts are unknown.</p>')
    rows = []
    for name, sp in plan.stages.items():
        s = last.get(name, {})
        stored = sum(plan.store.has(t.key) for t in sp.tasks)
        rows.append([name, sp.spec.function, sp.spec.fanout, len(sp.tasks), stored,
                     s.get("executed", "-"), s.get("cached", "-"), s.get("failed", "-"), s.get("skipped", "-"),
                     s.get("seconds", "-"), ctx["stage_seconds"].get(name) if ctx["stage_seconds"].get(name)
                     is not None else "-", sp.code[:12],
                     "" if rec_stages.get(name, {}).get("code") in (None, sp.code) else "changed since last run"])
    parts.append(table(["stage", "function", "fanout", "tasks", "in cache now", "executed (last run)",
                        "cached (last run)", "failed", "skipped", "seconds (last run)",
                        "compute seconds (stored results)", "code fingerprint", "code"], rows, cls="provenance"))
    if record:
        summ = record.get("summary") or {}
        note = f"; the last run was a no-op taking {summ['last_noop']} s" if "last_noop" in summ else ""
        parts.append(f"<p>Last run: {esc(_when(record.get('time')))}, wall time {esc(summ.get('wall_seconds', '?'))} s"
                     f"{esc(note)}; overrides <code>{esc(' '.join(record.get('overrides') or []) or '(none)')}</code>."
                     "</p>")
    parts.append("<h3>Stage parameters and code</h3>")
    for name, sp in plan.stages.items():
        code_rows = [[fn, digest[:16]] for fn, digest in sorted(sp.code_parts.items())]
        inner = ("<p>Parameters:</p>" + _json_pre(sp.spec.params)
                 + f"<p>Code fingerprint <code>{esc(sp.code)}</code>, from:</p>"
                 + table(["project function / constant", "fingerprint"], code_rows))
        parts.append(_folded(f"{name}: {sp.spec.function}", inner))
    parts.append("<h3>Pipeline parameters</h3>" + _json_pre(plan.pipeline.params))
    try:
        with open(plan.pipeline.file, encoding="utf-8") as fh:
            text = fh.read()
        digest = hashlib.blake2b(text.encode(), digest_size=16).hexdigest()
        parts.append(_folded(f"pipeline file {os.path.basename(plan.pipeline.file)} (blake2b {digest})",
                             f"<pre>{esc(text)}</pre>"))
    except OSError:
        pass
    parts.append("<h3>Environment</h3>")
    env_rows = [[k, v] for k, v in ctx["versions"].items()]
    env_rows += [["platform", platform.platform()], ["executable", sys.executable]]
    if ctx["git"]:
        env_rows.append(["git commit", ctx["git"]])
    parts.append(table(["package", "version"], env_rows, cls="versions"))
    return "".join(parts)


# ---------------------------------------------------------------------------------------------
# entry point
# ---------------------------------------------------------------------------------------------
def build_context(pipeline_path: str, overrides=(), cache_dir=None, out=None) -> dict:
    """Everything the report shows, gathered from the plan, store, run record, sweeps and output folder."""
    import time

    overrides = list(overrides or ())
    plan = plan_pipeline(pipeline_path, overrides, cache_dir, None, quiet=True)
    out_path = os.path.abspath(out or os.path.join(plan.pipeline.output_dir, "report.html"))
    record = load_record(plan)
    tasks = plan.tasks()
    stored = sum(plan.store.has(t.key) for t in tasks)
    record_keys = {(n, lbl): v.get("key") for n, s in (record or {}).get("stages", {}).items()
                   for lbl, v in s.get("tasks", {}).items()}
    record_differs = bool(record) and any(record_keys.get((t.stage, t.label)) != t.key for t in tasks)
    out_dir = plan.pipeline.output_dir
    earlier_reports = glob.glob(os.path.join(glob.escape(out_dir), "*.html"))
    files = published_files(out_dir, exclude=[out_path, *earlier_reports]) if os.path.isdir(out_dir) else []
    images = [f for f in files if os.path.splitext(f)[1].lower() in IMAGE_TYPES]
    caption_files = {_caption_file(f) for f in images} & set(files)
    figures_by_group: dict[str, list[str]] = {}
    for rel in images:
        group = rel.split("/", 1)[0] if "/" in rel else ""
        figures_by_group.setdefault(group, []).append(rel)
    return {
        "plan": plan, "record": record, "overrides": overrides, "pipeline_arg": pipeline_path,
        "out_path": out_path, "now": time.time(), "stored": stored, "total": len(tasks),
        "nothing_run": stored == 0, "incomplete": 0 < stored < len(tasks), "record_differs": record_differs,
        "metrics": pipeline_metrics(plan), "metric_origin": _metric_origins(plan), "sweeps": load_sweeps(plan),
        "files": files, "images": images, "caption_files": caption_files, "figures_by_group": figures_by_group,
        "other_files": [f for f in files if f not in images and f not in caption_files],
        "stage_seconds": _stage_seconds(plan), "versions": package_versions(),
        "git": _git_commit(os.path.dirname(os.path.abspath(__file__))),
    }


def render_html(ctx: dict) -> str:
    """The report page for a context from :func:`build_context`."""
    plan = ctx["plan"]
    by_problem: dict[str | None, list[str]] = {}
    for name, sp in plan.stages.items():
        by_problem.setdefault(problem_of(sp.spec.function), []).append(name)
    other_groups = [""] + sorted(g for g in ctx["figures_by_group"] if g and g not in plan.stages)
    sections: list[tuple[str, str, str]] = [("summary", "Summary", _summary_section(ctx))]
    has_problems = any(k is not None for k in by_problem)
    if has_problems:
        for _, key, title in PROBLEMS:
            if key in by_problem:
                body = _figures_block(ctx, by_problem[key]) or \
                    '<p class="muted">No figures published by these stages yet.</p>'
                stage_list = ", ".join(f"{n} ({plan.stages[n].spec.function})" for n in by_problem[key])
                sections.append((key, title, f"<p>Stages: {esc(stage_list)}.</p>{body}"))
        rest = _figures_block(ctx, by_problem.get(None, []), other_groups) + _files_section(ctx)
        if rest:
            sections.append(("figures", "Other figures and files", rest))
    else:
        body = _figures_block(ctx, list(plan.stages), other_groups)
        body = (body or '<p class="muted">No figures (PNG/SVG) in the output folder.</p>') + _files_section(ctx)
        sections.append(("figures", "Figures", body))
    sections += [("metrics", "Metrics", _metrics_section(ctx)), ("sweeps", "Sweeps", _sweeps_section(ctx)),
                 ("provenance", "Provenance", _provenance_section(ctx))]
    toc = "".join(f'<li><a href="#{sid}">{esc(title)}</a></li>' for sid, title, _ in sections)
    body = "".join(f'<section id="{sid}"><h2>{esc(title)}</h2>{content}</section>' for sid, title, content in sections)
    title = f"Pipeline report: {plan.pipeline.name}"
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{esc(title)}</title><style>{CSS}</style></head><body>"
            f"<h1>{esc(title)}</h1><p class=\"muted\">{esc(plan.pipeline.file)} &middot; written "
            f"{esc(_when(ctx['now']))}</p><nav><h2>Contents</h2><ul>{toc}</ul></nav>{body}</body></html>\n")


def write_report(pipeline_path: str, overrides=(), cache_dir: str | None = None, out: str | None = None) -> str:
    """Write the self-contained HTML report of a pipeline configuration; returns the file written.

    Args:
        pipeline_path: the pipeline YAML.
        overrides: ``key=value`` strings as for ``run --set`` (the configuration whose metrics are shown).
        cache_dir: the cache folder (default: the pipeline's ``cache:``).
        out: the HTML file (default: ``<output folder>/report.html``).
    """
    ctx = build_context(pipeline_path, overrides, cache_dir, out)
    atomic_write_text(ctx["out_path"], render_html(ctx))
    return ctx["out_path"]
