"""What a run would execute and why (``run --dry-run``, ``status``); runs and writes nothing."""
from __future__ import annotations

from .plan import Plan, plan_pipeline
from .record import load_record, pending_reason, reason


def dry_run(plan: Plan) -> list[dict]:
    """The tasks that would execute: ``[{"stage", "label", "key", "reason"}]`` in plan order; a stage that
    waits for a generated dataset (its tasks are planned once run has written it) is one row with key None."""
    record = load_record(plan)
    missing = {t.key for t in plan.missing()}
    rows = []
    for name, sp in plan.stages.items():
        if sp.pending is not None:
            rows.append({"stage": name, "label": "", "key": None, "reason": pending_reason(plan, name).text()})
        if sp.skipped is not None:
            rows.append({"stage": name, "label": "", "key": None, "reason": f"skipped: {sp.skipped}"})
        rows += [{"stage": t.stage, "label": t.label, "key": t.key, "reason": reason(t, plan, record)}
                 for t in sp.tasks if t.key in missing]
    return rows


def format_dry_run(plan: Plan, rows: list[dict], limit_per_stage: int = 8) -> str:
    """The dry-run report: per stage how many tasks would run, grouped by reason, then a total line."""
    lines = []
    total = {n: len(sp.tasks) for n, sp in plan.stages.items()}
    by_stage: dict[str, list[dict]] = {}
    for r in rows:
        by_stage.setdefault(r["stage"], []).append(r)
    for name, sp in plan.stages.items():
        todo = by_stage.get(name, [])
        if sp.pending is not None:
            lines.append(f"{name}: would run ({todo[0]['reason']})")
            continue
        if sp.skipped is not None:
            lines.append(f"{name}: skipped ({sp.skipped})")
            continue
        lines.append(f"{name}: {len(todo)} of {total[name]} task(s) would run" + ("" if todo else " (all cached)"))
        groups: dict[str, list[str]] = {}
        for r in todo:
            groups.setdefault(r["reason"], []).append(r["label"] or name)
        for why, labels in groups.items():
            shown = ", ".join(labels[:limit_per_stage]) + (f" ... (+{len(labels) - limit_per_stage})"
                                                           if len(labels) > limit_per_stage else "")
            lines.append(f"    {shown}: {why}")
    n_tasks = sum(r["key"] is not None for r in rows)
    waiting = [n for n, sp in plan.stages.items() if sp.pending is not None]
    lines.append(f"total: {n_tasks} task(s) would run, {sum(total.values()) - n_tasks} cached"
                 + (f"; {len(waiting)} stage(s) planned once run has generated "
                    f"{', '.join(sorted(plan.pending_generated))}" if waiting else ""))
    return "\n".join(lines)


def status(path: str, overrides=(), cache_dir=None) -> list[dict]:
    """Per stage: function, fanout, tasks, cached, to_run and the distinct reasons."""
    plan = plan_pipeline(path, overrides, cache_dir, None, quiet=True)
    rows = dry_run(plan)
    out = []
    for name, sp in plan.stages.items():
        mine = [r for r in rows if r["stage"] == name]
        todo = [r for r in mine if r["key"] is not None]
        to_run = len(todo) if sp.pending is None else None      # None: not known before generating
        out.append({"stage": name, "function": sp.spec.function, "fanout": sp.spec.fanout, "tasks": len(sp.tasks),
                    "cached": len(sp.tasks) - len(todo) if to_run is not None else 0, "to_run": to_run,
                    "reasons": sorted({r["reason"] for r in mine}), "skipped": sp.skipped})
    return out
