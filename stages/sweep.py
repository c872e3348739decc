"""``sweep``: run every point of a parameter grid in one task graph and tabulate (and plot) their metrics."""
from __future__ import annotations

import itertools
import json
import os
import re
import shutil
import textwrap
import time

from .errors import PipelineError
from .execute import execute_rounds
from .headline import best_indices, key_directions, sweep_columns
from .plan import plan_pipeline
from .publish import write_output_file
from .record import note_keys, pipeline_id
from .results import metrics, scalar_metrics
from .run import generated_names, prepare
from .session import client_session, stderr_log
from .status import dry_run, format_dry_run
from .checksums import digest_json, write_checked_json


def parse_grid(grids: list[str]) -> list[list[str]]:
    """``["mrf.sigma=0.5,1", "seed=0,1"]`` -> the cartesian product as lists of ``key=value`` overrides."""
    axes = []
    for g in grids:
        key, _, values = g.partition("=")
        points = [f"{key.strip()}={v.strip()}" for v in values.split(",") if v.strip() != ""]
        if "=" not in g or not key.strip() or not points:
            raise PipelineError(f"--grid '{g}' is not KEY=V1,V2,... (a parameter and at least one value)",
                                fix="e.g. --grid mrf.sigma=0.5,1,2 (a params key) or --grid STAGE.PARAM=1,2")
        axes.append(points)
    return [list(p) for p in itertools.product(*axes)]


def sweep_path(plan, grids: list[str], overrides) -> str:
    """The record of one sweep of ``plan``'s pipeline: ``<cache>/sweeps/<pipeline-id>-<hash of grid and
    overrides>.json`` (see stages.record.pipeline_id)."""
    sweep_id = pipeline_id(plan) + "-" + digest_json([grids, list(overrides)])[:8]
    return os.path.join(plan.store.root, "sweeps", sweep_id + ".json")


def sweep(path: str, grids: list[str], overrides=(), workers: int = 2, scheduler: str | None = None,
          cache_dir=None, quiet=False, dry: bool = False, metric_keys: list[str] | None = None, targets=(),
          force=()) -> dict:
    """Run every grid point (all points' misses in one task graph) and collect their metrics.

    Results are stored under their own keys, so points never overwrite each other, and an interrupted
    sweep resumes where it stopped. The sweep is recorded in cache/sweeps/ for the report.
    ``dry``: only check every point's configuration and say how many tasks each would run (runs, writes nothing);
    returns {"dry_run": [{"point": {key: value}, "to_run": n, "report": dry-run text}]}.
    ``metric_keys``: the headline columns (dotted keys or glob patterns; default: the plugins' choice, see
    :func:`headline_columns`), returned with their directions under "headline" for :func:`format_table`.
    ``targets`` and ``force``: as for ``run`` (stages.select), at every grid point; a task shared by several
    points is recomputed once.
    """
    log = stderr_log(quiet)
    points = parse_grid(grids)
    if dry:
        out = []
        for p in points:
            plan = plan_pipeline(path, list(overrides) + p, cache_dir, None, quiet=True, targets=targets, force=force)
            rows = dry_run(plan)
            out.append({"point": dict(x.split("=", 1) for x in p), "to_run": sum(r["key"] is not None for r in rows),
                        "report": format_dry_run(plan, rows)})
        return {"dry_run": out}
    plans = [prepare(plan_pipeline(path, list(overrides) + p, cache_dir, None, quiet=True, targets=targets,
                                   force=force), log) for p in points]
    store = plans[0].store
    missing = [t for pl in plans for t in pl.missing()]
    log(f"sweep: {len(points)} point(s), {len({t.key for t in missing})} task(s) to run")
    failures = []
    if missing or any(pl.waiting() for pl in plans):  # in rounds: stages waiting for candidates run once known
        with client_session(workers, scheduler, store.root, log) as get_client:
            plans, outcome, _ = execute_rounds(plans, get_client, quiet=quiet, log=log)
        failures = [{"stage": r.stage, "item": r.label, "error": r.error} for r in outcome.failed()]
    note_keys(plans[0], [t.key for pl in plans for t in pl.tasks()], [g for pl in plans for g in generated_names(pl)])
    rows = [{"point": dict(x.split("=", 1) for x in p), "metrics": metrics(pl)} for p, pl in zip(points, plans)]
    result = {"pipeline": os.path.abspath(path), "grid": grids, "overrides": list(overrides), "rows": rows,
              "failures": failures, "time": time.time(), "headline": headline_columns(plans[0], rows, metric_keys)}
    record = sweep_path(plans[0], grids, overrides)
    result["figure_file"] = figure_name(plans[0].pipeline.name, grids, overrides)
    write_checked_json(record, json.loads(json.dumps(result, default=str)))
    figure = os.path.join("sweeps", result["figure_file"])
    result["figure"] = plot_sweep(rows, plans[0].pipeline.output_dir, figure, first=result["headline"]["columns"])
    return result


def figure_name(pipeline_name: str, grids: list[str], overrides=()) -> str:
    """The file name of a sweep's plot: the pipeline and the swept parameters with their values
    (``shapecorr_align.sigma_scale=0.5,1,2.png``), plus a short hash of the fixed overrides when there are any."""
    safe = lambda text: re.sub(r"[^A-Za-z0-9._=,+-]+", "_", text).strip("_")  # noqa: E731
    name = "_".join([safe(pipeline_name) or "pipeline"] + [safe(g.replace(" ", "")) for g in grids])[:150]
    if overrides:
        name += "_with-" + digest_json(list(overrides))[:8]
    return name + ".png"


def _echoes_parameter(xs: list[float], values: list[float]) -> bool:
    """True when a metric only repeats the swept parameter: the same values, or a fixed multiple of them (e.g. a
    ``sigma`` that is ``sigma_scale`` times a constant)."""
    if any(x == 0 and v != 0 for x, v in zip(xs, values)):
        return False
    pairs = [(x, v) for x, v in zip(xs, values) if x != 0]
    if len(pairs) < 2:
        return False
    ratios = [v / x for x, v in pairs]
    return max(ratios) - min(ratios) <= 1e-9 * max(abs(r) for r in ratios)


def _varies(values: list[float]) -> bool:
    """More than float noise between the values (relative spread above 1e-9)."""
    lo, hi = min(values), max(values)
    return hi - lo > 1e-9 * max(abs(lo), abs(hi), 1e-300)


def plot_sweep(rows: list[dict], out_root: str, rel: str, max_panels: int = 8, first: list[str] = ()) -> str | None:
    """Plot the scalar metrics that vary across a one-axis numeric sweep against the swept value, leaving out
    constants and metrics that only repeat the swept parameter (``first``: the keys to plot first, e.g. the
    headline columns; then energies, accuracies, ...).

    Written to ``out_root/rel`` as a file of the engine's own (see :func:`stages.publish.write_output_file`).
    Returns the PNG written, or None when the sweep has several axes, one point, or nothing varies (or a file
    not written by the engine is in its place)."""
    axes_keys = list(dict.fromkeys(k for r in rows for k in r["point"]))
    if len(axes_keys) != 1 or len(rows) < 2:
        return None
    key = axes_keys[0]
    try:
        xs = [float(r["point"][key]) for r in rows]
    except ValueError:
        return None
    flat = [scalar_metrics(r["metrics"]) for r in rows]
    names = [n for n in dict.fromkeys(k for f in flat for k in f)
             if all(isinstance(f.get(n), (int, float)) and not isinstance(f.get(n), bool) for f in flat)
             and _varies([f[n] for f in flat]) and not _echoes_parameter(xs, [f[n] for f in flat])]
    preferred = [n for n in first if n in names]
    preferred += [n for n in names if n not in preferred and any(
        w in n for w in ("energy", "accuracy", "exact", "stability", "equivariance"))]
    names = (preferred + [n for n in names if n not in preferred])[:max_panels]
    if not names:
        return None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cols = min(4, len(names))
    nrows = (len(names) + cols - 1) // cols
    fig, axs = plt.subplots(nrows, cols, figsize=(3.4 * cols, 2.6 * nrows), squeeze=False)
    order = sorted(range(len(xs)), key=lambda i: xs[i])
    for ax, n in zip(axs.ravel(), names):
        ax.plot([xs[i] for i in order], [flat[i][n] for i in order], "o-")
        ax.set_xlabel(key)
        ax.set_title("\n".join(textwrap.wrap(n, 34, break_on_hyphens=False)), fontsize=9)
    for ax in axs.ravel()[len(names):]:
        ax.axis("off")
    fig.tight_layout()
    fig.set_layout_engine(None)     # laid out: savefig need not draw it once more first
    written = write_output_file(out_root, rel, lambda tmp: fig.savefig(tmp, dpi=100, format="png"),
                                where="the sweep's values are in the table and its record in the cache")
    plt.close(fig)
    return written


MAX_WIDTH = 120   # characters of the printed sweep table when the output is no terminal and COLUMNS is unset


def terminal_width(default: int = MAX_WIDTH) -> int:
    """Characters per line of the terminal (``COLUMNS`` first, then the terminal itself; ``default`` when the
    output goes to a file or pipe), at least 40."""
    return max(40, shutil.get_terminal_size((default, 24)).columns)


def headline_columns(plan, rows: list[dict], requested: list[str] | None = None) -> dict:
    """The columns of a sweep's headline table: {"columns": [dotted metric keys], "better": {key: "max"|"min"}}.

    ``requested``: keys or glob patterns (``--metrics``); default: the plugins' ``sweep_metrics``, else the
    cells of their headline tables. Raises PipelineError for a requested key no grid point has."""

    merged: dict = {}
    for r in rows:
        merged.update({k: v for k, v in r["metrics"].items() if k not in merged})
    columns = sweep_columns(plan, merged, requested)
    if requested and not columns:
        known = ", ".join(list(scalar_metrics(merged))[:40])
        raise PipelineError(f"--metrics {','.join(requested)}: no such metric in this sweep",
                            fix=f"name dotted metric keys or patterns such as 'accuracy.*'; known keys: {known}")
    if not columns:   # nothing declared: the first scalar metrics
        columns = list(scalar_metrics(merged))
    directions = key_directions(plan, merged)
    return {"columns": columns, "better": {k: directions[k] for k in columns if directions.get(k)}}


def _short(key: str, keys: list[str]) -> str:
    """The last two dotted parts of a key (group.measure: ``seed_stability.min``, ``accuracy.mrf``, never a bare
    ``min``), or more when those are not unique among ``keys``."""
    parts = key.split(".")
    for n in range(min(2, len(parts)), len(parts) + 1):
        tail = ".".join(parts[-n:])
        if sum(k == tail or k.endswith("." + tail) for k in keys) == 1:
            return tail
    return key


def _cell_text(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else ("" if v is None else str(v))


def format_table(rows: list[dict], headline: dict | None = None, width: int | None = None) -> str:
    """A plain-text table: one row per grid point, its point values then the headline metrics, at most
    ``width`` characters wide (default: the terminal's, :func:`terminal_width`), notes wrapped to it too; the best
    value of each column whose direction is known ends with ``*``. Headers are the metric keys, or group.measure,
    or (when that is still too wide) the group above the measure on two lines, before columns are left out.

    headline: {"columns": [...], "better": {...}} (see :func:`headline_columns`); None: every scalar metric
    (then columns that do not fit are left out, with a note)."""
    width = width or terminal_width()
    cols_point = list(dict.fromkeys(k for r in rows for k in r["point"]))
    flat = [scalar_metrics(r["metrics"]) for r in rows]
    cols_m = list((headline or {}).get("columns") or dict.fromkeys(k for f in flat for k in f))
    better = (headline or {}).get("better", {})

    columns = []
    for c in cols_m:
        values = [f.get(c) for f in flat]
        best = best_indices(values, better.get(c))
        columns.append([_cell_text(v) + ("*" if i in best else "") for i, v in enumerate(values)])
    body_point = [[str(r["point"].get(c, "")) for c in cols_point] for r in rows]

    def render(labels: list[str], shown: int, two_rows: bool = False) -> list[str]:
        """The table with ``shown`` metric columns; ``two_rows``: each header split at its last dot, the group
        above the measure (narrower columns)."""
        header = cols_point + labels[:shown]
        rows = [[h.rpartition(".")[0] for h in header], [h.rpartition(".")[2] for h in header]] if two_rows \
            else [header]
        body = [bp + [col[i] for col in columns[:shown]] for i, bp in enumerate(body_point)]
        widths = [max(*(len(r[i]) for r in rows + body), 0) for i in range(len(header))]
        fmt = lambda cells: "  ".join(c.rjust(w) if j >= len(cols_point) else c.ljust(w)  # noqa: E731
                                      for j, (c, w) in enumerate(zip(cells, widths))).rstrip()
        return [fmt(r) for r in rows] + [fmt(["-" * w for w in widths])] + [fmt(b) for b in body]

    def note(text: str) -> list[str]:
        return textwrap.wrap(text, width, subsequent_indent="  ", break_on_hyphens=False)

    short = [_short(c, cols_m) for c in cols_m]
    label_sets = [(cols_m, False)] + ([(short, False)] if short != cols_m else []) + [(short, True)]
    for labels, two_rows in label_sets:
        for shown in range(len(cols_m), 0, -1):
            lines = render(labels, shown, two_rows)
            if max(len(x) for x in lines) <= width:
                if shown < len(cols_m):
                    lines += note(f"({len(cols_m) - shown} more column(s) do not fit: see --csv or --metrics)")
                if labels is not cols_m:
                    lines += note("columns: " + ", ".join(cols_m[:shown]))
                if better:
                    lines.append("* best of the column")
                return "\n".join(lines)
            if (labels, two_rows) != label_sets[-1]:
                break   # these labels do not fit: try shorter ones before dropping columns
    lines = render(short, 1, True)   # not even one metric column fits: the point values and the first column
    return "\n".join([x[:width] for x in lines] + note("columns: " + cols_m[0] if cols_m else ""))


def write_table(rows: list[dict], path: str) -> str:
    """The full sweep table (every scalar metric of every point) as CSV, or as JSON when ``path`` ends in
    ``.json`` (the rows with their nested metrics). Returns ``path``."""
    import csv

    if path.lower().endswith(".json"):
        with open(path, "w", encoding="utf-8") as fh:
            json.dump(rows, fh, indent=2, default=str)
        return path
    cols_point = list(dict.fromkeys(k for r in rows for k in r["point"]))
    flat = [scalar_metrics(r["metrics"]) for r in rows]
    cols_m = list(dict.fromkeys(k for f in flat for k in f))
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(cols_point + [f"{c} (metric)" if c in cols_point else c for c in cols_m])
        for r, f in zip(rows, flat):
            w.writerow([r["point"].get(c, "") for c in cols_point] + [f.get(c, "") for c in cols_m])
    return path
