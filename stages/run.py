"""``run``: compute a pipeline's cache misses, publish its files, record the run.

Usable from Python::

    from stages.run import run
    summary = run("pipeline.yaml", overrides=["mrf.sigma=0.5"], workers=2)
"""
from __future__ import annotations

import json
import os
import sys
import time

from .errors import CorruptEntry, UserError, warn_once
from .execute import clean_tmp, execute_rounds
from .generated import write_generated
from .plan import Plan, build_plan, plan_pipeline
from .publish import check_output_folder, publish, verify_published, write_output_file
from .record import build_record, load_record, note_keys, save_record
from .results import metrics
from .session import client_session, given_client, stderr_log
from .status import dry_run, format_dry_run
from .checksums import atomic_write_text
from .worker import TaskResult, TaskStatus


class RunFailed(Exception):
    """Some tasks failed (everything else finished and is stored); ``summary`` says which."""

    def __init__(self, summary: dict):
        self.summary = summary
        super().__init__(f"{len(summary['failures'])} task(s) failed")


def stage_summary(plan: Plan, outcome_results: dict[str, TaskResult], missing_keys: set[str]) -> dict:
    """Per stage: tasks, executed, cached, failed, skipped (inputs failed), items_skipped (executed tasks whose
    function returned ``Skipped``) and summed compute seconds of this run."""
    out = {}
    for name, sp in plan.stages.items():
        ex = [outcome_results[t.key] for t in sp.tasks if t.key in outcome_results]
        count = lambda status: sum(r.status is status for r in ex)  # noqa: E731
        out[name] = {
            "tasks": len(sp.tasks),
            "executed": count(TaskStatus.OK),
            "cached": sum(t.key not in missing_keys or (t.key in outcome_results and
                                                        outcome_results[t.key].status is TaskStatus.CACHED)
                          for t in sp.tasks),
            "failed": count(TaskStatus.FAILED),
            "skipped": count(TaskStatus.SKIPPED),
            "items_skipped": sum(bool(r.item_skipped) for r in ex),
            "seconds": round(sum(r.seconds for r in ex), 4),
        }
        if sp.skipped is not None:  # the stage has no tasks: an input it needs is absent
            out[name]["skipped_stage"] = sp.skipped
        if sp.waiting is not None:  # no tasks: the candidates stage it waits for did not succeed
            out[name]["waiting_for"] = sp.waiting
    return out


def prepare(plan: Plan, log, on_claimed=None) -> Plan:
    """Make a plan executable: write the generated datasets it waits for (then plan again, so their stages
    get tasks) and save the planner's caches. Only ``run`` and ``sweep`` call this; planning alone writes
    nothing. ``on_claimed()``, when given, is called once the cache folder is claimed and writable, before the
    datasets are written."""
    check_output_folder(plan.pipeline.output_dir, plan.store.root)
    plan.store.claim()
    if not plan.store.writable():
        raise UserError(f"cannot write the cache folder {plan.store.root} (read-only, or no permission)",
                        fix="run with --cache on a writable folder; `status`, `results`, `report` and "
                            "`run --dry-run` work on a read-only cache")
    if on_claimed is not None:
        on_claimed()
    if plan.pending_generated:
        write_generated(plan.pipeline, plan.store, sorted(plan.pending_generated), log)
        plan = plan.again()
    plan.save_caches()
    return plan


def generated_names(plan: Plan) -> list[str]:
    """The folder names under ``cache/generated`` of the generated datasets ``plan`` uses."""
    return [os.path.basename(g.path) for g in plan.pipeline.generated.values() if g.path]


def run(path: str, overrides=(), workers: int = 2, scheduler: str | None = None, dry: bool = False,
        cache_dir: str | None = None, output_dir: str | None = None, quiet: bool = False,
        summary_json: str | None = None, client_getter=None, max_repairs: int = 2, targets=(),
        force=()) -> dict:
    """Run a pipeline: compute the cache misses, publish outputs, record the run.

    ``targets``: stage names; only they and the stages they need run (and are published); ``metrics.json`` is
    written by runs of the whole pipeline only. ``force``: stage names recomputed, with their downstream stages,
    even when cached (the stored results are replaced, see Store.put). Before executing, one line per stage says
    how many tasks run and why (see stages.status.run_lines); ``quiet`` drops it (failures are still printed).
    Returns the summary dict (per stage: tasks, executed, cached, failed, skipped, seconds).
    Raises RunFailed when a task failed (after everything else finished and was stored).
    """
    log = stderr_log(quiet)
    t0 = time.time()
    plan = plan_pipeline(path, overrides, cache_dir, output_dir, quiet, targets=targets, force=force)
    if dry:
        rows = dry_run(plan)
        print(format_dry_run(plan, rows))
        return {"dry_run": rows}
    clean_tmp(plan.store)
    results: dict[str, TaskResult] = {}
    missing_all: set[str] = set()
    with (client_session(workers, scheduler, plan.store.root, log) if client_getter is None
          else given_client(client_getter)) as get_client:
        # something will run: start the cluster while the generated datasets are written
        early = getattr(get_client, "start_early", None)
        listed = None if plan.pending_generated else (plan, plan.missing())   # this plan's misses, for round one
        plan = prepare(plan, log, on_claimed=early if early and (listed is None or listed[1]) else None)
        record_before = load_record(plan)
        verified: dict[str, dict[str, str]] = {}
        for attempt in range(max_repairs + 1):
            # in rounds: stages waiting for a candidates stage are planned (and run) once its result is stored
            (plan,), outcome, missing = execute_rounds([plan], get_client, quiet=quiet, log=log if attempt == 0 else None,
                                                       key_suffix=f"-repair{attempt}" if attempt else "",
                                                       first_missing=[listed] if listed else None)
            missing_all |= missing
            results.update(outcome.results)
            corrupt: list[tuple[str, str]] = [(r.corrupt_key, r.error) for r in outcome.corrupt()]  # (key, what)
            if not corrupt:  # the files to publish are checked before publishing: a bad one is recomputed now
                verified, bad = verify_published(plan)
                corrupt = [(exc.key, str(exc)) for exc in bad]
            if not corrupt:
                break
            for key, error in corrupt:
                warn_once(f"{error}; recomputing it")  # once, through the engine's reporter (not also a UserWarning)
                plan.store.invalidate(key)
            plan = plan.again()
    try:
        published = publish(plan, log, verified)
    except CorruptEntry as exc:  # changed while this run was publishing
        plan.store.invalidate(exc.key)
        log(f"warning: {exc}; run again to recompute it")
        published = []
    summary = {"pipeline": plan.pipeline.file, "stages": stage_summary(plan, results, missing_all),
               "failures": [{"stage": r.stage, "item": r.label, "error": r.error, "traceback": r.traceback}
                            for r in results.values() if r.status is TaskStatus.FAILED],
               "skipped": [r.display for r in results.values() if r.status is TaskStatus.SKIPPED],
               "items_skipped": [{"stage": r.stage, "item": r.label, "why": r.item_skipped}
                                 for r in results.values() if r.item_skipped],
               "wall_seconds": round(time.time() - t0, 3), "published": len(published)}
    record = build_record(plan, summary, previous=record_before)
    if record_before and not any(s["executed"] for s in summary["stages"].values()):
        record["summary"] = record_before.get("summary", summary) | {"last_noop": summary["wall_seconds"]}
    save_record(plan, record)
    note_keys(plan, [t.key for t in plan.tasks()], generated_names(plan))
    m = metrics(plan)  # also when items failed: the metrics then list the items they left out (_left_out)
    if m and not plan.untargeted:  # a run of some targets does not replace the whole pipeline's metrics
        try:
            write_output_file(plan.pipeline.output_dir, "metrics.json", lambda tmp: atomic_write_text(
                tmp, json.dumps(m, indent=2, default=str)))
        except OSError as exc:
            raise UserError(f"cannot write {os.path.join(plan.pipeline.output_dir, 'metrics.json')}: "
                            f"{exc.strerror or exc}", fix="make the output folder writable or use --out FOLDER") from None
    if summary_json:
        os.makedirs(os.path.dirname(os.path.abspath(summary_json)), exist_ok=True)
        atomic_write_text(summary_json, json.dumps(summary, indent=2))
    for stage, warnings in (m or {}).get("_warnings", {}).items():   # a metrics stage's "check this" sentences
        for w in warnings:
            log(f"warning ({stage}): {w}")
    for f in summary["failures"]:  # printed even with --quiet: which item failed, and why
        print(f"FAILED {f['stage']}[{f['item']}]: {f['error']}", file=sys.stderr, flush=True)
    for item in summary["items_skipped"]:   # computed, stored, and not an error: the function said why
        log(f"{item['stage']}[{item['item']}]: skipped: {item['why']}")
    if summary["skipped"]:
        log(f"skipped {len(summary['skipped'])} task(s) whose inputs failed")
    if summary["failures"]:
        raise RunFailed(summary)
    return summary
