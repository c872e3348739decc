"""The report's sections (summary, figures, other files, metrics, sweeps), each ``f(ctx) -> HTML``."""
from __future__ import annotations

import os
from urllib.parse import quote

from ..headline import HeadlineTable, best_indices
from ..results import scalar_metrics
from ..sweep import headline_columns
from .context import ReportContext, caption_file
from .markup import (anchor, data_uri, esc, folded, format_value, human_size, is_scalar, render_value, scroll_box,
                     table, when)


def _run_line(ctx: ReportContext) -> str:
    """One paragraph: pipeline, data, when it ran and what ran vs came from the cache."""
    plan, record = ctx.plan, ctx.record
    items = [f"{name} {len(src.items)}" for name, src in plan.datasets.items() if getattr(src, "items", None)]
    gen = [f"{g.name} = {g.generator}(" + ", ".join(f"{k}={v}" for k, v in g.params.items()) + ")"
           for g in (plan.pipeline.generated or {}).values()]
    data = "items: " + (", ".join(items) or "none")
    if gen:
        data += "; generated: " + "; ".join(gen)
    parts = [f"<b>{esc(plan.pipeline.name)}</b> (<code>{esc(os.path.basename(plan.pipeline.file))}</code>"
             + (f", <code>{esc(' '.join(ctx.overrides))}</code>" if ctx.overrides else "") + ")",
             f"data {esc(data)}"]
    if record:
        stages = (record.get("summary") or {}).get("stages", {})
        executed = sum(int(s.get("executed", 0) or 0) for s in stages.values())
        cached = sum(int(s.get("cached", 0) or 0) for s in stages.values())
        wall = (record.get("summary") or {}).get("wall_seconds", "?")
        parts.append(f"last run {esc(when(record.get('time')))} ({esc(wall)} s): <b>{executed}</b> task(s) ran, "
                     f"<b>{cached}</b> came from the cache")
    else:
        parts.append("no run recorded")
    parts.append(f"{ctx.stored} of {ctx.total} results in the cache")
    return '<p class="runline">' + " &middot; ".join(parts) + "</p>"


def _cache_rows(store) -> list[list[str]]:
    """The run-details rows naming the cache: where the entries live as the user gave it (a folder, or the URL of
    an object store), and for an object store also its local folder (temporary files, run records)."""
    rows = [["cache", store.location]]
    if store.location != store.root:
        rows.append(["cache local folder", store.root])
    return rows


def _short_number(v) -> str:
    """A summary cell: 3 significant digits (the full values are in the metrics details)."""
    return f"{v:.3g}" if isinstance(v, float) else format_value(v)


def headline_table_html(t: HeadlineTable) -> str:
    """A headline table: rows x measures, the best value of each column bold with a star."""
    best = [t.best_rows(c) for c in range(len(t.columns))]
    head = "".join(f"<th>{esc(h)}</th>" for h in ["method"] + t.columns)
    body = []
    for r, row in enumerate(t.rows):
        cells = [f"<td>{esc(row)}</td>"]
        for c, v in enumerate(t.cells[r]):
            if v is None:
                cells.append('<td class="num muted">&ndash;</td>')
            elif r in best[c]:
                cells.append(f'<td class="num best" title="best">&#9733;&nbsp;{esc(_short_number(v))}</td>')
            else:
                cells.append(f'<td class="num">{esc(_short_number(v))}</td>')
        body.append(f"<tr>{''.join(cells)}</tr>")
    return scroll_box(f'<table class="summary-table"><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody>'
                      "</table>")


def _headline_block(ctx: ReportContext, t: HeadlineTable) -> str:
    figs = "".join(figure_html(ctx, rel, thumb=True) for rel in t.figures)
    return (f'<div class="problem"><div class="ptable"><h3>{esc(t.title)}</h3>{headline_table_html(t)}'
            f'<p class="muted small">&#9733; best per column; &ndash;: not measured. Details, per-mesh values and '
            f'every figure below.</p></div><div class="pfigs">{figs}</div></div>')


def summary_section(ctx: ReportContext) -> str:
    """The first screen: what ran on which data, then per problem the headline table and its key figures."""
    plan, record, m = ctx.plan, ctx.record, ctx.metrics
    parts = [_run_line(ctx)]
    cmd = f"python -m stages run {ctx.pipeline_arg}" + "".join(f" --set {o}" for o in ctx.overrides)
    if ctx.nothing_run:
        parts.append(f'<p class="note"><b>Nothing has been run yet</b> for this configuration: no result is in '
                     f"the cache <code>{esc(plan.store.location)}</code>. Run <code>{esc(cmd)}</code> and then "
                     f"<code>python -m stages report {esc(ctx.pipeline_arg)}</code> again.</p>")
    elif ctx.incomplete:
        parts.append(f'<p class="note">Not every task of this configuration is in the cache '
                     f"({ctx.stored} of {ctx.total} stored). To complete it run <code>{esc(cmd)}</code>.</p>")
    same_overrides = record is not None and list(record.get("overrides") or []) == list(ctx.overrides)
    if record and ctx.record_differs and same_overrides:
        parts.append('<p class="note">The code, the data or the pipeline file changed since the last recorded run '
                     "(same overrides): published figures and files come from that run; metrics and cache counts "
                     f"below are for the current state. Run <code>{esc(cmd)}</code> to bring them together.</p>")
    elif record and ctx.record_differs:
        parts.append('<p class="note">The last recorded run of this pipeline file used a different configuration '
                     f"(overrides: <code>{esc(' '.join(record.get('overrides') or []) or '(none)')}</code>) "
                     "than this report (overrides: "
                     f"<code>{esc(' '.join(ctx.overrides) or '(none)')}</code>). Published figures and files come "
                     "from that last run; metrics and cache counts below are for this configuration.</p>")
    if "_not_computed" in m:
        parts.append(f'<p class="bad">Metrics not computed yet: {esc(", ".join(m["_not_computed"]))}.</p>')
    for stage, items in m.get("_left_out", {}).items():  # computed without items that failed upstream
        parts.append(f'<p class="bad">{esc(stage)} left out {len(items)} failed item(s): '
                     + esc("; ".join(f"{x['item']}: {x['why']}" for x in items[:20])) + ".</p>")
    for stage, why in m.get("_skipped", {}).items():
        parts.append(f'<p class="note">{esc(stage)} skipped: {esc(why)}.</p>')
    for stage, warnings in m.get("_warnings", {}).items():     # a stage's own "check this" sentences
        parts.append("".join(f'<p class="bad warning">{esc(stage)}: {esc(w)}</p>' for w in warnings[:20])
                     + (f'<p class="bad">{esc(stage)}: {len(warnings) - 20} more warning(s) in '
                        "<code>results --json</code>.</p>" if len(warnings) > 20 else ""))
    parts += [_headline_block(ctx, t) for t in ctx.headlines]
    rows = [["pipeline", plan.pipeline.name], ["file", plan.pipeline.file],
            ["overrides", " ".join(ctx.overrides) or "(none)"], ["output folder", plan.pipeline.output_dir],
            *_cache_rows(plan.store), ["results in cache", f"{ctx.stored} of {ctx.total} tasks"]]
    if record:
        summ = record.get("summary") or {}
        rows += [["last run", when(record.get("time"))], ["last run wall time (s)", summ.get("wall_seconds", "?")]]
    rows.append(["report written", when(ctx.now)])
    head = scalar_metrics(m)
    scalars = table(["metric", "value"], [[k, v] for k, v in head.items()], cls="scalar-metrics") if head else ""
    if not ctx.headlines and len(head) <= 16:
        parts.append(("<h3>Metrics</h3>" + scalars) if scalars else "")
        parts.append(folded("run details", table(["", ""], rows)))
    else:
        parts.append(folded("run details", table(["", ""], rows)))
        if scalars:
            parts.append(folded(f"every scalar metric ({len(head)})", scalars))
    return "".join(parts)


def figure_link(ctx: ReportContext, rel: str) -> str:
    """The URL of a published figure relative to the report file (a plain link that opens it full size)."""
    target = os.path.join(ctx.output_dir, rel)
    try:
        href = os.path.relpath(target, os.path.dirname(os.path.abspath(ctx.out_path)))
    except ValueError:   # another drive (Windows)
        href = os.path.abspath(target)
    return "/".join(quote(part, safe="=,+") for part in href.replace(os.sep, "/").split("/"))


def figure_html(ctx: ReportContext, rel: str, thumb: bool = False) -> str:
    """One embedded figure, a link to the full-size file, with its caption file (if any) and its path;
    ``thumb``: the summary's smaller form."""
    folder, _, file = rel.rpartition("/")
    caption = f'<span class="muted">in <code>{esc(folder)}/</code></span>' if folder else ""
    cap_rel = caption_file(rel)
    if cap_rel in ctx.caption_files:
        with open(os.path.join(ctx.output_dir, cap_rel), encoding="utf-8", errors="replace") as fh:
            caption += f"<pre>{esc(fh.read().strip())}</pre>"
    title = os.path.splitext(file)[0]     # the file's own name (e.g. dense_dense_auto: method dense_auto)
    cls = ' class="thumb"' if thumb else ""
    return (f'<figure{cls}><a class="full" href="{esc(figure_link(ctx, rel))}" target="_blank" '
            f'title="open {esc(rel)} full size"><img src="{data_uri(os.path.join(ctx.output_dir, rel))}" '
            f'alt="{esc(title)}" title="{esc(rel)}"></a><figcaption><b>{esc(title)}</b> {caption}</figcaption>'
            "</figure>")


def _figure_or_pointer(ctx: ReportContext, rel: str, placed: dict[str, str]) -> str:
    """The figure, or (for one another section embeds: each image is in the file once) a pointer to it."""
    if rel in placed:
        return (f'<figure class="pointer"><figcaption><code>{esc(rel)}</code>: shown in '
                f'<a href="#{placed[rel]}">{esc(placed[rel])}</a></figcaption></figure>')
    return figure_html(ctx, rel)


def figures_block(ctx: ReportContext, stage_names: list[str], extra_groups: list[str] = ()) -> str:
    """The figures of the given stages (and of other top-level folders), one subsection each."""
    plan, parts = ctx.plan, []
    for group in list(stage_names) + list(extra_groups):
        figs = ctx.figures_by_group.get(group, [])
        if not figs:
            continue
        if group in plan.stages:
            sp = plan.stages[group]
            fanout = {"item": "per item", "pair": "per pair tile"}.get(sp.spec.fanout, "once")
            label = f"{group} ({sp.spec.function}, {fanout})"
        else:
            label = "pipeline folder (sweep and summary figures)" if group == "" else f"{group} (not a stage)"
        parts.append(f'<h3 id="fig-{anchor(group or "top")}">{esc(label)}: {len(figs)} figure(s)</h3>')
        placed = ctx.placed
        grid = f'<div class="figs">{"".join(_figure_or_pointer(ctx, rel, placed) for rel in figs)}</div>'
        parts.append(grid if len(figs) <= 24 else folded(f"{len(figs)} figures", grid, open_=True))
    return "".join(parts)


def files_section(ctx: ReportContext) -> str:
    """The published files that are not figures, with sizes (not embedded)."""
    if not ctx.other_files:
        return ""
    rows = []
    for rel in ctx.other_files:
        try:
            size = os.path.getsize(os.path.join(ctx.output_dir, rel))
        except OSError:
            size = 0
        rows.append([rel, human_size(size)])
    inner = table(["file (relative to the output folder)", "size"], rows)
    return (f"<h3>Other published files</h3><p>Under <code>{esc(ctx.output_dir)}</code> (not embedded).</p>"
            + (inner if len(rows) <= 40 else folded(f"{len(rows)} files", inner)))


def metrics_section(ctx: ReportContext) -> str:
    """Every metric, by the stage that produced it: scalars in a table, structures rendered below."""
    plan, m = ctx.plan, ctx.metrics
    shown = {k: v for k, v in m.items() if not k.startswith("_")}
    if not shown:
        return "<p>No metrics computed yet" + (
            " (no stage of this pipeline is marked <code>metrics: true</code>)." if not any(
                sp.spec.metrics for sp in plan.stages.values()) else ".") + "</p>"
    by_stage: dict[str, list[str]] = {}
    for k in shown:
        by_stage.setdefault(ctx.metric_origin.get(k, "?"), []).append(k)
    parts = []
    for stage, keys in by_stage.items():
        sp = plan.stages.get(stage)
        inner = []
        scalars = [[k, shown[k]] for k in keys if is_scalar(shown[k])]
        if scalars:
            inner.append(table(["metric", "value"], scalars))
        for k in keys:
            if not is_scalar(shown[k]):
                inner.append(f"<h4>{esc(k)}</h4>{render_value(shown[k])}")
        title = f"{stage} ({sp.spec.function})" if sp else "metrics"
        parts.append(f"<h3>{esc(title)}</h3>" + folded(f"{len(keys)} metric(s): {', '.join(keys)}", "".join(inner)))
    return "".join(parts)


def _sweep_table(sw: dict, columns: list[str] | None = None, better: dict | None = None, cls: str = "sweep") -> str:
    """One row per grid point: its point values, then the metric ``columns`` (default every scalar metric),
    the best value of each column with a known direction marked."""
    rows = sw.get("rows", [])
    point_cols = list(dict.fromkeys(k for r in rows for k in r.get("point", {})))
    flat = [scalar_metrics(r.get("metrics") or {}) for r in rows]
    metric_cols = list(columns) if columns else list(dict.fromkeys(k for f in flat for k in f))
    best = {c: best_indices([f.get(c) for f in flat], (better or {}).get(c)) for c in metric_cols}
    body = []
    for i, (r, f) in enumerate(zip(rows, flat)):
        missing = (r.get("metrics") or {}).get("_not_computed")
        cells = [esc(r["point"].get(c, "")) for c in point_cols]
        for c in metric_cols:
            v = f.get(c, "")
            text = esc(format_value(v))
            cells.append(f'<span class="best">&#9733;&nbsp;{text}</span>' if i in best[c] else text)
        body.append(cells + [esc(", ".join(missing)) if missing else ""])
    header = point_cols + [f"{c} (metric)" if c in point_cols else c for c in metric_cols] + ["not computed"]
    return table(header, body, cls=cls, raw_cols=tuple(range(len(header))))


def _sweep_headline(ctx: ReportContext, sw: dict) -> dict:
    """The headline columns of a recorded sweep (as ``sweep`` printed them; computed for older records)."""
    if sw.get("headline", {}).get("columns"):
        return sw["headline"]
    try:
        return headline_columns(ctx.plan, sw.get("rows", []))
    except Exception:  # an unreadable old record: show every column
        return {"columns": [], "better": {}}


def sweeps_section(ctx: ReportContext) -> str:
    """One table per recorded sweep: a row per grid point with its scalar metrics, then its failures."""
    if not ctx.sweeps:
        return (f"<p>No sweep recorded for this pipeline file. Run e.g. <code>python -m stages sweep "
                f"{esc(ctx.pipeline_arg)} --grid KEY=V1,V2</code>.</p>")
    parts = []
    for i, sw in enumerate(ctx.sweeps, 1):
        grid = " ".join(f"--grid {g}" for g in sw.get("grid", []))
        parts.append(f"<h3>Sweep {i}: <code>{esc(grid)}</code></h3>")
        parts.append(f"<p>{len(sw.get('rows', []))} point(s), run {esc(when(sw.get('time')))}"
                     + (f", fixed overrides <code>{esc(' '.join(sw['overrides']))}</code>" if sw.get("overrides")
                        else "") + ".</p>")
        head = _sweep_headline(ctx, sw)
        parts.append(_sweep_table(sw, head.get("columns"), head.get("better")))
        fig = ctx.sweep_figure(sw)
        if fig:
            parts.append(f'<div class="figs">{figure_html(ctx, fig)}</div>')
        parts.append(folded("the full table: every scalar metric of every point", _sweep_table(sw, cls="sweep-full")))
        if sw.get("failures"):
            parts.append(f'<p class="bad">{len(sw["failures"])} task(s) failed:</p>'
                         + table(["stage", "item", "error"],
                                 [[f.get("stage"), f.get("item"), f.get("error")] for f in sw["failures"][:50]]))
    return "".join(parts)
