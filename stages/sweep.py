"""``sweep``: run every point of a parameter grid in one task graph and tabulate (and plot) their metrics."""
from __future__ import annotations

import itertools
import json
import os
import time

from .errors import PipelineError
from .execute import execute_rounds
from .plan import plan_pipeline
from .publish import write_output_file
from .record import pipeline_id
from .results import metrics, scalar_metrics
from .run import prepare
from .session import client_session, stderr_log
from .status import dry_run, format_dry_run
from .store import digest_json, write_checked_json


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


def sweep_path(store_root: str, path: str, grids: list[str], overrides) -> str:
    """The record of one sweep: ``<cache>/sweeps/<pipeline-id>-<hash of grid and overrides>.json``."""
    sweep_id = pipeline_id(path) + "-" + digest_json([grids, list(overrides)])[:8]
    return os.path.join(store_root, "sweeps", sweep_id + ".json")


def sweep(path: str, grids: list[str], overrides=(), workers: int = 2, scheduler: str | None = None,
          cache_dir=None, quiet=False, dry: bool = False, metric_keys: list[str] | None = None) -> dict:
    """Run every grid point (all points' misses in one task graph) and collect their metrics.

    Results are stored under their own keys, so points never overwrite each other, and an interrupted
    sweep resumes where it stopped. The sweep is recorded in cache/sweeps/ for the report.
    ``dry``: only check every point's configuration and say how many tasks each would run (runs, writes nothing);
    returns {"dry_run": [{"point": {key: value}, "to_run": n, "report": dry-run text}]}.
    ``metric_keys``: the headline columns (dotted keys or glob patterns; default: the plugins' choice, see
    :func:`headline_columns`), returned with their directions under "headline" for :func:`format_table`.
    """
    log = stderr_log(quiet)
    points = parse_grid(grids)
    if dry:
        out = []
        for p in points:
            plan = plan_pipeline(path, list(overrides) + p, cache_dir, None, quiet=True)
            rows = dry_run(plan)
            out.append({"point": dict(x.split("=", 1) for x in p), "to_run": sum(r["key"] is not None for r in rows),
                        "report": format_dry_run(plan, rows)})
        return {"dry_run": out}
    plans = [prepare(plan_pipeline(path, list(overrides) + p, cache_dir, None, quiet=True), log) for p in points]
    store = plans[0].store
    missing = [t for pl in plans for t in pl.missing()]
    log(f"sweep: {len(points)} point(s), {len(missing)} task(s) to run")
    failures = []
    if missing or any(pl.waiting() for pl in plans):  # in rounds: stages waiting for candidates run once known
        with client_session(workers, scheduler, store.root, log) as get_client:
            plans, outcome, _ = execute_rounds(plans, get_client, quiet=quiet)
        failures = [{"stage": r.stage, "item": r.label, "error": r.error} for r in outcome.failed()]
    rows = [{"point": dict(x.split("=", 1) for x in p), "metrics": metrics(pl)} for p, pl in zip(points, plans)]
    result = {"pipeline": os.path.abspath(path), "grid": grids, "overrides": list(overrides), "rows": rows,
              "failures": failures, "time": time.time(), "headline": headline_columns(plans[0], rows, metric_keys)}
    record = sweep_path(store.root, path, grids, overrides)
    write_checked_json(record, json.loads(json.dumps(result, default=str)))
    figure = os.path.join("sweeps", os.path.basename(record)[:-5] + ".png")
    result["figure"] = plot_sweep(rows, plans[0].pipeline.output_dir, figure, first=result["headline"]["columns"])
    return result


def plot_sweep(rows: list[dict], out_root: str, rel: str, max_panels: int = 8, first: list[str] = ()) -> str | None:
    """Plot the scalar metrics that vary across a one-axis numeric sweep against the swept value
    (``first``: the keys to plot first, e.g. the headline columns; then energies, accuracies, ...).

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
             and len({f[n] for f in flat}) > 1]
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
        ax.set_title(n, fontsize=8)
    for ax in axs.ravel()[len(names):]:
        ax.axis("off")
    fig.tight_layout()
    written = write_output_file(out_root, rel, lambda tmp: fig.savefig(tmp, dpi=100, format="png"),
                                where="the sweep's values are in the table and its record in the cache")
    plt.close(fig)
    return written


MAX_WIDTH = 120   # characters of the printed sweep table


def headline_columns(plan, rows: list[dict], requested: list[str] | None = None) -> dict:
    """The columns of a sweep's headline table: {"columns": [dotted metric keys], "better": {key: "max"|"min"}}.

    ``requested``: keys or glob patterns (``--metrics``); default: the plugins' ``sweep_metrics``, else the
    cells of their headline tables. Raises PipelineError for a requested key no grid point has."""
    from .report.headline import key_directions, sweep_columns

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


def _short(key: str, keys: list[str], min_len: int = 5) -> str:
    """The last dotted part of a key, or more parts when the last one is not unique among ``keys`` or too short
    to say what it is (``seed_stability.min``, not ``min``)."""
    parts = key.split(".")
    for n in range(1, len(parts) + 1):
        tail = ".".join(parts[-n:])
        if sum(k == tail or k.endswith("." + tail) for k in keys) == 1 and (len(tail) >= min_len or n == len(parts)):
            return tail
    return key


def _cell_text(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else ("" if v is None else str(v))


def format_table(rows: list[dict], headline: dict | None = None, width: int = MAX_WIDTH) -> str:
    """A plain-text table: one row per grid point, its point values then the headline metrics, at most
    ``width`` characters wide; the best value of each column whose direction is known ends with ``*``.

    headline: {"columns": [...], "better": {...}} (see :func:`headline_columns`); None: every scalar metric
    (then columns that do not fit are left out, with a note)."""
    cols_point = list(dict.fromkeys(k for r in rows for k in r["point"]))
    flat = [scalar_metrics(r["metrics"]) for r in rows]
    cols_m = list((headline or {}).get("columns") or dict.fromkeys(k for f in flat for k in f))
    better = (headline or {}).get("better", {})
    from .report.headline import best_indices

    columns = []
    for c in cols_m:
        values = [f.get(c) for f in flat]
        best = best_indices(values, better.get(c))
        columns.append([_cell_text(v) + ("*" if i in best else "") for i, v in enumerate(values)])
    body_point = [[str(r["point"].get(c, "")) for c in cols_point] for r in rows]

    def render(labels: list[str], shown: int) -> list[str]:
        header = cols_point + labels[:shown]
        body = [bp + [col[i] for col in columns[:shown]] for i, bp in enumerate(body_point)]
        widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h) for i, h in enumerate(header)]
        fmt = lambda cells: "  ".join(c.rjust(w) if j >= len(cols_point) else c.ljust(w)  # noqa: E731
                                      for j, (c, w) in enumerate(zip(cells, widths))).rstrip()
        return [fmt(header), fmt(["-" * w for w in widths])] + [fmt(b) for b in body]

    label_sets = (cols_m, [_short(c, cols_m) for c in cols_m], [_short(c, cols_m, 1) for c in cols_m])
    for labels in label_sets:
        for shown in range(len(cols_m), 0, -1):
            lines = render(labels, shown)
            if max(len(x) for x in lines) <= width:
                if shown < len(cols_m):
                    lines.append(f"({len(cols_m) - shown} more column(s) do not fit: see --csv or --metrics)")
                if labels is not cols_m:
                    lines.append("columns: " + ", ".join(cols_m[:shown]))
                if better:
                    lines.append("* best of the column")
                return "\n".join(lines)
            if labels is not label_sets[-1]:
                break   # these labels do not fit: try shorter ones before dropping columns
    return "\n".join(render([_short(c, cols_m) for c in cols_m], 1))


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
