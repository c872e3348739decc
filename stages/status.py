"""What a run would execute and why (``run --dry-run``, ``status``); runs and writes nothing."""
from __future__ import annotations

from .plan import Plan, Task, plan_pipeline
from .record import load_record, pending_reason, reason


def dry_run(plan: Plan) -> list[dict]:
    """The tasks that would execute: ``[{"stage", "label", "key", "reason"}]`` in plan order; a stage that
    waits for a generated dataset (its tasks are planned once run has written it), or for the result of a
    candidates stage (a pair stage on a candidate graph and what is downstream of it), is one row with key None."""
    record = load_record(plan)
    missing = {t.key for t in plan.missing()}
    rows = []
    for name, sp in plan.stages.items():
        if sp.pending is not None:
            rows.append({"stage": name, "label": "", "key": None, "reason": pending_reason(plan, name).text()})
        if sp.skipped is not None:
            rows.append({"stage": name, "label": "", "key": None, "reason": f"skipped: {sp.skipped}"})
        if sp.waiting is not None:
            rows.append({"stage": name, "label": "", "key": None, "reason": waiting_reason(plan, name)})
        rows += [{"stage": t.stage, "label": t.label, "key": t.key, "reason": reason(t, plan, record)}
                 for t in sp.tasks if t.key in missing]
    return rows


def run_lines(tasks: list[tuple[Task, Plan]]) -> list[str]:
    """What ``run`` prints before executing ``tasks`` ((task, its plan) pairs): one line per stage, its number of
    tasks and the first reason, compared with the plan's last recorded run (as Snakemake prints a reason per
    job), e.g. ``dense_refine: 20 tasks (code changed: corr_core.dense.deform.refine_deform)``; when the tasks of a
    stage run for several reasons, how many others (``--dry-run`` lists them all)."""
    records: dict[int, dict | None] = {}
    reasons: dict[str, list[str]] = {}
    for task, plan in tasks:
        if id(plan) not in records:
            records[id(plan)] = load_record(plan)
        reasons.setdefault(task.stage, []).append(reason(task, plan, records[id(plan)]))
    lines = []
    for stage, why in reasons.items():
        others = len(set(why)) - 1
        more = f"; and {others} other reason{'s' if others > 1 else ''}: see --dry-run" if others else ""
        lines.append(f"{stage}: {len(why)} task{'s' if len(why) != 1 else ''} ({why[0]}{more})")
    return lines


def waiting_reason(plan: Plan, stage: str) -> str:
    """Why a stage has no tasks yet: it waits for the result of a candidates stage."""
    sp = plan.stages[stage]
    own = sp.spec.candidates == sp.waiting
    what = ("its tasks are the candidate pairs that stage returns" if own else
            "it reads a pair stage whose tasks are the candidate pairs that stage returns")
    return f"once stage '{sp.waiting}' has run ({what}; {sp.waiting_detail or 'not computed yet'})"


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
        if sp.waiting is not None:
            lines.append(f"{name}: would run {todo[0]['reason']}")
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
    checkpoints = sorted({sp.waiting for sp in plan.stages.values() if sp.waiting is not None})
    n_waiting = sum(sp.waiting is not None for sp in plan.stages.values())
    lines.append(f"total: {n_tasks} task(s) would run, {sum(total.values()) - n_tasks} cached"
                 + (f"; {len(waiting)} stage(s) planned once run has generated "
                    f"{', '.join(sorted(plan.pending_generated))}" if waiting else "")
                 + (f"; {n_waiting} stage(s) planned once {', '.join(checkpoints)} has run" if checkpoints else ""))
    return "\n".join(lines)


def status(path: str, overrides=(), cache_dir=None) -> list[dict]:
    """Per stage: function, fanout, tasks, cached, to_run and the distinct reasons."""
    plan = plan_pipeline(path, overrides, cache_dir, None, quiet=True)
    rows = dry_run(plan)
    out = []
    for name, sp in plan.stages.items():
        mine = [r for r in rows if r["stage"] == name]
        todo = [r for r in mine if r["key"] is not None]
        known = sp.pending is None and sp.waiting is None
        to_run = len(todo) if known else None      # None: not known before generating / the candidates exist
        row = {"stage": name, "function": sp.spec.function, "fanout": sp.spec.fanout, "tasks": len(sp.tasks),
               "cached": len(sp.tasks) - len(todo) if to_run is not None else 0, "to_run": to_run,
               "reasons": sorted({r["reason"] for r in mine}), "skipped": sp.skipped}
        if sp.waiting is not None:
            row["waiting_for"] = sp.waiting
        out.append(row)
    return out
