"""The record of a pipeline's last run, and the reasons a task will (re)run.

Each run writes ``cache/runs/<pipeline-id>.json``: per stage the code fingerprint and its parts, the params,
and per task its key and input digests, plus timings. ``--dry-run`` and ``status`` compare the planned
tasks with this record to say *why* each cache miss runs: which param, which input item, or which
project function changed.
"""
from __future__ import annotations

import json
import os
import time

from .plan import Plan, Task
from .store import atomic_write_text, digest_json


def pipeline_id(plan_or_file) -> str:
    path = plan_or_file if isinstance(plan_or_file, str) else plan_or_file.pipeline.file
    return os.path.splitext(os.path.basename(path))[0] + "-" + digest_json(os.path.abspath(path))[:10]


def record_path(plan: Plan) -> str:
    return os.path.join(plan.store.root, "runs", pipeline_id(plan) + ".json")


def load_record(plan: Plan) -> dict | None:
    try:
        with open(record_path(plan), encoding="utf-8") as fh:
            return json.load(fh)
    except (FileNotFoundError, json.JSONDecodeError):
        return None


def build_record(plan: Plan, summary: dict | None = None, extra: dict | None = None) -> dict:
    stages = {}
    for name, sp in plan.stages.items():
        stages[name] = {
            "function": sp.spec.function, "fanout": sp.spec.fanout, "code": sp.code, "code_parts": sp.code_parts,
            "params": sp.spec.params, "input_items": sp.input_items,
            "tasks": {t.label: {"key": t.key, "inputs": t.input_digests} for t in sp.tasks},
        }
    rec = {"pipeline": plan.pipeline.file, "name": plan.pipeline.name, "time": time.time(),
           "overrides": plan.pipeline.overrides, "params": plan.pipeline.params, "stages": stages,
           "summary": summary or {}}
    rec.update(extra or {})
    return rec


def save_record(plan: Plan, record: dict) -> None:
    atomic_write_text(record_path(plan), json.dumps(record, default=str))


def _short(v) -> str:
    text = json.dumps(v, default=str)
    return text if len(text) <= 40 else text[:37] + "..."


def _item_suffix(plan: Plan, task: Task, ref) -> str:
    """'[item]' when the input is one item of a collection, '' when it is a single value or a whole collection."""
    if ref is None:
        return ""
    if ref.item is not None:
        return f"[{ref.item}]"
    source = plan.datasets.get(ref.source) or (plan.stages[ref.source].source if ref.source in plan.stages else None)
    per_item = source is not None and source.kind == "items"
    if per_item and not ref.whole and plan.stages[task.stage].spec.fanout == "item":
        return f"[{task.label}]"
    return ""


def reason(task: Task, plan: Plan, record: dict | None) -> str:
    """Why ``task`` (a cache miss) will run, compared with the last recorded run."""
    sp = plan.stages[task.stage]
    if record is None:
        return "no earlier run of this pipeline"
    prev_stage = record["stages"].get(task.stage)
    if prev_stage is None:
        return "new stage"
    prev = prev_stage["tasks"].get(task.label)
    if prev is None:
        return "new item" if task.label and sp.spec.fanout == "item" else \
            "new tile (the items in it changed)" if sp.spec.fanout == "pair" else "not run before"
    if prev["key"] == task.key:
        return "result missing from the cache (deleted or found corrupt)"
    why = []
    if prev_stage["function"] != sp.spec.function:
        why.append(f"function {prev_stage['function']} -> {sp.spec.function}")
    if prev_stage["code"] != sp.code:
        old, new = prev_stage.get("code_parts", {}), sp.code_parts
        changed = sorted(k for k in new if old.get(k) != new[k])
        gone = sorted(k for k in old if k not in new)
        what = ", ".join(changed + [f"{g} (no longer used)" for g in gone]) or "fingerprint"
        why.append(f"code changed: {what}")
    if prev_stage["params"] != sp.spec.params:
        for k in sorted(set(prev_stage["params"]) | set(sp.spec.params)):
            a, b = prev_stage["params"].get(k, "<unset>"), sp.spec.params.get(k, "<unset>")
            if a != b:
                why.append(f"param {k}: {_short(a)} -> {_short(b)}")
    for arg, digest in task.input_digests.items():
        if prev["inputs"].get(arg) == digest:
            continue
        ref = sp.spec.inputs.get(arg)
        src = ref.source if ref else arg
        old_items, new_items = prev_stage.get("input_items", {}).get(arg), sp.input_items.get(arg)
        if old_items is not None and new_items is not None:
            added = sorted(set(new_items) - set(old_items))
            removed = sorted(set(old_items) - set(new_items))
            changed = sorted(k for k in new_items if k in old_items and new_items[k] != old_items[k])
            bits = []
            for label, lst in (("added", added), ("removed", removed), ("changed", changed)):
                if lst:
                    bits.append(f"{label} {', '.join(lst[:5])}{' ...' if len(lst) > 5 else ''}")
            why.append(f"input {arg} ({src}): {'; '.join(bits) or 'changed'}")
        else:
            why.append(f"input {arg} ({src}{_item_suffix(plan, task, ref)}) changed")
    return "; ".join(why) or "key changed"
