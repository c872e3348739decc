"""The engine's operations behind the CLI: run, dry-run, status, results, sweep, gc.

Usable from Python too::

    from stages.runner import run
    summary = run("pipeline.yaml", overrides=["mrf.sigma=0.5"], workers=2)
"""
from __future__ import annotations

import itertools
import json
import os
import shutil
import sys
import time
import warnings
from contextlib import contextmanager
from typing import Any

from . import registry
from .config import load_pipeline
from .errors import CorruptEntry
from .execute import clean_tmp, execute, make_client
from .plan import Plan, build_plan
from .record import build_record, load_record, pipeline_id, reason, save_record
from .store import Store, atomic_write_text, digest_json


class RunFailed(Exception):
    """Some tasks failed; the summary says which."""

    def __init__(self, summary: dict):
        self.summary = summary
        super().__init__(f"{len(summary['failures'])} task(s) failed")


def _log(quiet: bool):
    return (lambda *a, **k: None) if quiet else (lambda *a, **k: print(*a, **k, file=sys.stderr, flush=True))


@contextmanager
def client_session(workers: int, scheduler: str | None, cache_dir: str):
    """Lazily start a dask client (only when something must run); close it at the end."""
    holder: dict[str, Any] = {}

    def get():
        if "client" not in holder:
            if workers == 0 and not scheduler:
                holder["client"] = None
            else:
                local = os.path.join(cache_dir, "tmp", "dask-worker-space")
                os.makedirs(local, exist_ok=True)
                holder["client"] = make_client(workers, scheduler, local_dir=local)
        return holder["client"]

    try:
        yield get
    finally:
        client = holder.get("client")
        if client is not None:
            cluster = getattr(client, "cluster", None)
            client.close()
            if cluster is not None and not scheduler:
                cluster.close()


def plan_pipeline(path: str, overrides=(), cache_dir=None, output_dir=None, quiet=False) -> Plan:
    pipe = load_pipeline(path, overrides, cache_dir=cache_dir, output_dir=output_dir)
    return build_plan(pipe, log=_log(quiet))


def dry_run(plan: Plan) -> list[dict]:
    """The tasks that would execute, each with its reason."""
    record = load_record(plan)
    return [{"stage": t.stage, "label": t.label, "key": t.key, "reason": reason(t, plan, record)}
            for t in plan.missing()]


def format_dry_run(plan: Plan, rows: list[dict], limit_per_stage: int = 8) -> str:
    lines = []
    total = {n: len(sp.tasks) for n, sp in plan.stages.items()}
    by_stage: dict[str, list[dict]] = {}
    for r in rows:
        by_stage.setdefault(r["stage"], []).append(r)
    for name in plan.stages:
        todo = by_stage.get(name, [])
        lines.append(f"{name}: {len(todo)} of {total[name]} task(s) would run" + ("" if todo else " (all cached)"))
        groups: dict[str, list[str]] = {}
        for r in todo:
            groups.setdefault(r["reason"], []).append(r["label"] or name)
        for why, labels in groups.items():
            shown = ", ".join(labels[:limit_per_stage]) + (f" ... (+{len(labels) - limit_per_stage})"
                                                           if len(labels) > limit_per_stage else "")
            lines.append(f"    {shown}: {why}")
    lines.append(f"total: {len(rows)} task(s) would run, "
                 f"{sum(total.values()) - len(rows)} cached")
    return "\n".join(lines)


def _stage_summary(plan: Plan, outcome_results: dict[str, dict], missing_keys: set[str]) -> dict:
    out = {}
    for name, sp in plan.stages.items():
        ex = [outcome_results[t.key] for t in sp.tasks if t.key in outcome_results]
        out[name] = {
            "tasks": len(sp.tasks),
            "executed": sum(r["status"] == "ok" for r in ex),
            "cached": sum(t.key not in missing_keys or outcome_results.get(t.key, {}).get("status") == "cached"
                          for t in sp.tasks),
            "failed": sum(r["status"] == "failed" for r in ex),
            "skipped": sum(r["status"] == "skipped" for r in ex),
            "seconds": round(sum(r.get("seconds", 0.0) for r in ex), 4),
        }
    return out


def publish(plan: Plan, log) -> list[str]:
    """Copy the files of every file-writing stage from the cache to the output folder."""
    out_root = plan.pipeline.output_dir
    written = []
    for name, sp in plan.stages.items():
        fn = registry.get(sp.spec.function)
        if "out_dir" not in fn.engine_args:
            continue
        target = os.path.join(out_root, name)
        if not all(plan.store.has(t.key) for t in sp.tasks):
            continue
        shutil.rmtree(target, ignore_errors=True)
        for t in sp.tasks:
            files = plan.store.verify_files(t.key)
            base = os.path.join(target, t.label) if sp.spec.fanout == "item" else target
            for rel, src in files.items():
                dst = os.path.join(base, rel)
                os.makedirs(os.path.dirname(dst), exist_ok=True)
                shutil.copyfile(src, dst)
                written.append(dst)
    return written


def metrics(plan: Plan) -> dict:
    """The merged values of the stages marked ``metrics: true`` (None when not computed yet)."""
    merged: dict[str, Any] = {}
    missing = []
    for name, sp in plan.stages.items():
        if not sp.spec.metrics:
            continue
        for t in sp.tasks:
            if not plan.store.has(t.key):
                missing.append(name)
                continue
            value = plan.store.get(t.key)
            if isinstance(value, dict):
                for k, v in value.items():
                    merged[k] = v
            else:
                merged[name] = value
    if missing:
        merged["_not_computed"] = sorted(set(missing))
    return merged


def run(path: str, overrides=(), workers: int = 2, scheduler: str | None = None, dry: bool = False,
        cache_dir: str | None = None, output_dir: str | None = None, quiet: bool = False,
        summary_json: str | None = None, client_getter=None, max_repairs: int = 2) -> dict:
    """Run a pipeline: compute the cache misses, publish outputs, record the run.

    Returns the summary dict (per stage: tasks, executed, cached, failed, skipped, seconds).
    Raises RunFailed when a task failed (after everything else finished and was stored).
    """
    log = _log(quiet)
    t0 = time.time()
    plan = plan_pipeline(path, overrides, cache_dir, output_dir, quiet)
    if dry:
        rows = dry_run(plan)
        print(format_dry_run(plan, rows))
        return {"dry_run": rows}
    clean_tmp(plan.store)
    record_before = load_record(plan)
    results: dict[str, dict] = {}
    missing_all: set[str] = set()
    with (client_session(workers, scheduler, plan.store.root) if client_getter is None
          else _given(client_getter)) as get_client:
        for attempt in range(max_repairs + 1):
            missing = plan.missing()
            missing_all |= {t.key for t in missing}
            if not missing:
                break
            if attempt == 0:
                reasons: dict[str, int] = {}
                for t in missing:
                    reasons[t.stage] = reasons.get(t.stage, 0) + 1
                log(f"running {len(missing)} task(s): " + ", ".join(f"{s} {n}" for s, n in reasons.items()))
            outcome = execute(missing, plan.store, get_client(), quiet=quiet,
                              key_suffix=f"-repair{attempt}" if attempt else "")
            results.update(outcome.results)
            corrupt = outcome.corrupt()
            if not corrupt:
                break
            for r in corrupt:
                warnings.warn(f"{r['error']}; recomputing it", stacklevel=1)
                log(f"warning: {r['error']}; recomputing it")
                plan.store.invalidate(r["corrupt_key"])
            plan = build_plan(plan.pipeline, log=log)
    try:
        published = publish(plan, log)
    except CorruptEntry as exc:
        plan.store.invalidate(exc.key)
        log(f"warning: {exc}; run again to recompute it")
        published = []
    summary = {"pipeline": plan.pipeline.file, "stages": _stage_summary(plan, results, missing_all),
               "failures": [{"stage": r["stage"], "item": r["label"], "error": r.get("error", ""),
                             "traceback": r.get("traceback", "")}
                            for r in results.values() if r["status"] == "failed"],
               "skipped": [r["display"] for r in results.values() if r["status"] == "skipped"],
               "wall_seconds": round(time.time() - t0, 3), "published": len(published)}
    record = build_record(plan, summary)
    if record_before and not any(s["executed"] for s in summary["stages"].values()):
        record["summary"] = record_before.get("summary", summary) | {"last_noop": summary["wall_seconds"]}
    save_record(plan, record)
    if not summary["failures"]:
        m = metrics(plan)
        if m:
            atomic_write_text(os.path.join(plan.pipeline.output_dir, "metrics.json"),
                              json.dumps(m, indent=2, default=str))
    if summary_json:
        os.makedirs(os.path.dirname(os.path.abspath(summary_json)), exist_ok=True)
        atomic_write_text(summary_json, json.dumps(summary, indent=2))
    for f in summary["failures"]:
        log(f"FAILED {f['stage']}[{f['item']}]: {f['error']}")
    if summary["skipped"]:
        log(f"skipped {len(summary['skipped'])} task(s) whose inputs failed")
    if summary["failures"]:
        raise RunFailed(summary)
    return summary


@contextmanager
def _given(getter):
    yield getter


def parse_grid(grids: list[str]) -> list[list[str]]:
    """``["mrf.sigma=0.5,1", "seed=0,1"]`` -> the cartesian product as lists of ``key=value`` overrides."""
    axes = []
    for g in grids:
        if "=" not in g:
            raise ValueError(f"--grid '{g}' is not key=v1,v2,...")
        key, _, values = g.partition("=")
        axes.append([f"{key}={v}" for v in values.split(",") if v != ""])
    return [list(p) for p in itertools.product(*axes)]


def sweep(path: str, grids: list[str], overrides=(), workers: int = 2, scheduler: str | None = None,
          cache_dir=None, quiet=False) -> dict:
    """Run every grid point (all points' misses in one task graph) and collect their metrics.

    Results are stored under their own keys, so points never overwrite each other, and an interrupted
    sweep resumes where it stopped. The sweep is recorded in cache/sweeps/ for the report.
    """
    log = _log(quiet)
    points = parse_grid(grids)
    plans = [plan_pipeline(path, list(overrides) + p, cache_dir, None, quiet=True) for p in points]
    store = plans[0].store
    missing = [t for pl in plans for t in pl.missing()]
    log(f"sweep: {len(points)} point(s), {len(missing)} task(s) to run")
    failures = []
    if missing:
        with client_session(workers, scheduler, store.root) as get_client:
            outcome = execute(missing, store, get_client(), quiet=quiet)
        failures = [{"stage": r["stage"], "item": r["label"], "error": r.get("error", "")} for r in outcome.failed()]
    rows = []
    for p, pl in zip(points, plans):
        rows.append({"point": dict(x.split("=", 1) for x in p), "metrics": metrics(pl)})
    result = {"pipeline": os.path.abspath(path), "grid": grids, "overrides": list(overrides), "rows": rows,
              "failures": failures, "time": time.time()}
    sweep_id = pipeline_id(path) + "-" + digest_json([grids, list(overrides)])[:8]
    atomic_write_text(os.path.join(store.root, "sweeps", sweep_id + ".json"), json.dumps(result, default=str))
    result["figure"] = plot_sweep(rows, os.path.join(plans[0].pipeline.output_dir, "sweeps", sweep_id + ".png"))
    return result


def plot_sweep(rows: list[dict], path: str, max_panels: int = 8) -> str | None:
    """Plot the scalar metrics that vary across a one-axis numeric sweep against the swept value."""
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
    preferred = [n for n in names if any(w in n for w in ("energy", "accuracy", "exact", "stability", "equivariance"))]
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
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def scalar_metrics(m: dict, prefix: str = "") -> dict[str, Any]:
    """Flatten nested metric dicts to dotted keys, keeping numbers and short strings only."""
    out = {}
    for k, v in m.items():
        if k.startswith("_"):
            continue
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            if len(v) <= 12:
                out.update(scalar_metrics(v, name + "."))
        elif isinstance(v, bool) or isinstance(v, (int, float)):
            out[name] = v
        elif isinstance(v, str) and len(v) < 20:
            out[name] = v
    return out


def format_table(rows: list[dict]) -> str:
    cols_point = list(dict.fromkeys(k for r in rows for k in r["point"]))
    flat = [scalar_metrics(r["metrics"]) for r in rows]
    cols_m = list(dict.fromkeys(k for f in flat for k in f))
    header = cols_point + cols_m
    body = []
    for r, f in zip(rows, flat):
        cells = [str(r["point"].get(c, "")) for c in cols_point]
        for c in cols_m:
            v = f.get(c, "")
            cells.append(f"{v:.4g}" if isinstance(v, float) else str(v))
        body.append(cells)
    widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h) for i, h in enumerate(header)]
    fmt = lambda cells: "  ".join(c.ljust(w) for c, w in zip(cells, widths))  # noqa: E731
    return "\n".join([fmt(header), fmt(["-" * w for w in widths])] + [fmt(b) for b in body])


def gc(paths: list[str], cache_dir: str | None = None, dry: bool = False, keep_sweeps: bool = True) -> dict:
    """Remove cache entries that none of the given pipelines (current configuration, and their recorded
    sweeps when ``keep_sweeps``) reaches; also removes temporary leftovers."""
    reachable: set[str] = set()
    store = None
    generated_keep: set[str] = set()
    for p in paths:
        plan = plan_pipeline(p, (), cache_dir, None, quiet=True)
        store = plan.store
        reachable |= {t.key for t in plan.tasks()}
        generated_keep |= {os.path.basename(g.path) for g in plan.pipeline.generated.values()}
        if keep_sweeps:
            sweeps_dir = os.path.join(store.root, "sweeps")
            for fn in os.listdir(sweeps_dir) if os.path.isdir(sweeps_dir) else []:
                if fn.startswith(pipeline_id(p)):
                    with open(os.path.join(sweeps_dir, fn), encoding="utf-8") as fh:
                        sw = json.load(fh)
                    for point in parse_grid(sw["grid"]):
                        try:
                            pl = plan_pipeline(p, sw.get("overrides", []) + point, cache_dir, None, quiet=True)
                            reachable |= {t.key for t in pl.tasks()}
                        except Exception:
                            pass
    store = store or Store(cache_dir or "cache")
    removed = [k for k in store.all_keys() if k not in reachable]
    freed = 0
    for k in removed:
        for path in (store.object_path(k), store.files_path(k)):
            freed += _du(path)
        if not dry:
            store.remove(k)
    gen_dir = os.path.join(store.root, "generated")
    gen_removed = [g for g in (os.listdir(gen_dir) if os.path.isdir(gen_dir) else []) if g not in generated_keep]
    for g in gen_removed:
        freed += _du(os.path.join(gen_dir, g))
        if not dry:
            shutil.rmtree(os.path.join(gen_dir, g), ignore_errors=True)
    if not dry:
        clean_tmp(store, older_than_s=0)
    return {"kept": len(store.all_keys()) if not dry else len(store.all_keys()) - len(removed),
            "removed": len(removed), "generated_removed": len(gen_removed), "bytes_freed": freed, "dry_run": dry}


def _du(path: str) -> int:
    total = 0
    for dirpath, _, files in os.walk(path):
        for f in files:
            try:
                total += os.path.getsize(os.path.join(dirpath, f))
            except OSError:
                pass
    return total


def status(path: str, overrides=(), cache_dir=None) -> list[dict]:
    """Per stage: tasks, cached, to run, and the reasons."""
    plan = plan_pipeline(path, overrides, cache_dir, None, quiet=True)
    rows = dry_run(plan)
    out = []
    for name, sp in plan.stages.items():
        todo = [r for r in rows if r["stage"] == name]
        out.append({"stage": name, "function": sp.spec.function, "fanout": sp.spec.fanout, "tasks": len(sp.tasks),
                    "cached": len(sp.tasks) - len(todo), "to_run": len(todo),
                    "reasons": sorted({r["reason"] for r in todo})})
    return out
