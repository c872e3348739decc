"""The record of a pipeline's last run, and the reasons a task will (re)run.

Each run writes ``cache/runs/<pipeline-id>.json``: per stage the code fingerprint and its parts, the params,
and per task its key and input digests, plus timings. ``--dry-run``, ``status`` and ``run`` compare the planned
tasks with this record to say *why* each cache miss runs: which param, which input item, or which
project function changed. The pipeline id names the pipeline, not where its file or the cache lie (see
:func:`pipeline_id`), so the reasons stay right after a project or its cache is moved or copied.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from typing import Any

from .config import Pipeline
from .plan import Plan, SourceKind, Task
from .checksums import digest_json, read_checked_json, write_checked_json


def pipeline_id(plan: "Plan | Pipeline") -> str:
    """The pipeline's identity in a cache: ``<file stem>-<hash of its name>``.

    Neither the folder of the pipeline file nor the cache's location is part of it: a project copied or moved
    elsewhere (pipeline, data and cache together), or a cache copied, finds its records again. Two files with
    the same stem and ``name:`` share it (they also share their output folder ``results/<name>``)."""
    pipe = plan.pipeline if isinstance(plan, Plan) else plan
    return os.path.splitext(os.path.basename(pipe.file))[0] + "-" + digest_json({"name": pipe.name})[:10]


def legacy_pipeline_id(plan: "Plan | Pipeline") -> str:
    """The id of caches written before :func:`pipeline_id` (it hashed the absolute path of the file): still read."""
    pipe = plan.pipeline if isinstance(plan, Plan) else plan
    return os.path.splitext(os.path.basename(pipe.file))[0] + "-" + digest_json(os.path.abspath(pipe.file))[:10]


def record_path(plan: Plan) -> str:
    return os.path.join(plan.store.root, "runs", pipeline_id(plan) + ".json")


def load_record(plan: Plan) -> dict | None:
    """The last run's record, or None (also when the file is unusable: warned once, then rewritten).

    A cache written before the pipeline id was location-free is read under its old id."""
    for pid in (pipeline_id(plan), legacy_pipeline_id(plan)):
        path = os.path.join(plan.store.root, "runs", pid + ".json")
        record = read_checked_json(path, "the reasons shown compare with no earlier run")
        if record is not None and isinstance(record.get("stages"), dict):
            return record
    return None


LEDGER_SUFFIX = ".keys.json"


def ledger_path(plan: Plan) -> str:
    """``cache/runs/<pipeline-id>.keys.json``: every entry and generated dataset the runs and sweeps of this
    pipeline planned (what ``gc`` may remove on its behalf, and never on another pipeline's)."""
    return os.path.join(plan.store.root, "runs", pipeline_id(plan) + LEDGER_SUFFIX)


def note_keys(plan: Plan, keys, generated=()) -> None:
    """Add ``keys`` (cache entries) and ``generated`` (folder names under ``cache/generated``) to the pipeline's
    ledger (:func:`ledger_path`); written only when something is new. Two runs of one pipeline at once may drop
    each other's additions: those entries then belong to no pipeline, which ``gc`` removes only with ``--all``."""
    path = ledger_path(plan)
    old = read_checked_json(path, "it is written again") or {}
    known, known_gen = set(old.get("keys", [])), set(old.get("generated", []))
    if set(keys) <= known and set(generated) <= known_gen and old.get("name") == plan.pipeline.name:
        return
    write_checked_json(path, {"pipeline": plan.pipeline.file, "name": plan.pipeline.name,
                              "keys": sorted(known | set(keys)), "generated": sorted(known_gen | set(generated))})


@dataclass
class Owner:
    """A pipeline as a cache knows it from its records: ``label`` (``name (file)``), the entries and generated
    datasets its recorded runs reference."""
    label: str
    keys: set
    generated: set


def owners(store_root: str) -> dict[str, Owner]:
    """{pipeline id: Owner} from every ledger and run record under ``cache/runs`` (a record alone, as written
    before ledgers existed, references the keys of that pipeline's last run)."""
    folder = os.path.join(store_root, "runs")
    out: dict[str, Owner] = {}
    for fn in sorted(os.listdir(folder)) if os.path.isdir(folder) else []:
        if not fn.endswith(".json"):
            continue
        ledger = fn.endswith(LEDGER_SUFFIX)
        pid = fn[:-len(LEDGER_SUFFIX)] if ledger else fn[:-5]
        doc = read_checked_json(os.path.join(folder, fn), "gc treats its entries as belonging to no pipeline")
        if not doc:
            continue
        label = f"{doc.get('name', pid)} ({os.path.basename(str(doc.get('pipeline', '?')))})"
        owner = out.setdefault(pid, Owner(label, set(), set()))
        if ledger:
            owner.keys |= set(doc.get("keys", []))
            owner.generated |= set(doc.get("generated", []))
        else:
            owner.keys |= {t.get("key") for st in doc.get("stages", {}).values() if isinstance(st, dict)
                           for t in st.get("tasks", {}).values() if isinstance(t, dict)}
    return out


def sweep_record_files(plan: Plan) -> list[str]:
    """The files under ``cache/sweeps/`` that record sweeps of this pipeline (see stages.sweep.sweep_path)."""
    folder = os.path.join(plan.store.root, "sweeps")
    prefixes = tuple(pid + "-" for pid in (pipeline_id(plan), legacy_pipeline_id(plan)))
    names = sorted(os.listdir(folder)) if os.path.isdir(folder) else []
    return [os.path.join(folder, fn) for fn in names if fn.startswith(prefixes) and fn.endswith(".json")]


def build_record(plan: Plan, summary: dict | None = None, extra: dict | None = None,
                 previous: dict | None = None) -> dict:
    """The record of a run of ``plan``; the stages it left out (``Plan.untargeted``: a run of some targets) keep
    their entry of the ``previous`` record, so later reasons compare them with the run that last planned them."""
    stages = {}
    for name, sp in plan.stages.items():
        stages[name] = {
            "function": sp.spec.function, "fanout": sp.spec.fanout, "code": sp.code, "code_parts": sp.code_parts,
            "params": sp.spec.params, "input_items": sp.input_items,
            "tasks": {t.label: {"key": t.key, "inputs": t.input_digests} for t in sp.tasks},
        }
    earlier = (previous or {}).get("stages", {})
    stages.update({n: earlier[n] for n in plan.untargeted if n in earlier})
    rec = {"pipeline": plan.pipeline.file, "name": plan.pipeline.name, "time": time.time(),
           "overrides": plan.pipeline.overrides, "params": plan.pipeline.params, "stages": stages,
           "summary": summary or {}}
    rec.update(extra or {})
    return rec


def save_record(plan: Plan, record: dict) -> None:
    write_checked_json(record_path(plan), json.loads(json.dumps(record, default=str)))


def _short(v) -> str:
    text = json.dumps(v, default=str)
    return text if len(text) <= 40 else text[:37] + "..."


def _listed(names: tuple[str, ...], limit: int = 5) -> str:
    return ", ".join(names[:limit]) + (" ..." if len(names) > limit else "")


@dataclass(frozen=True)
class InputChange:
    """One input argument whose identity differs from the last run.

    For a whole collection whose per-item identities were recorded: the items ``added``, ``removed`` and
    ``changed``; otherwise just that it changed (``item``: "[name]" when the input is one item).
    """
    arg: str
    source: str
    item: str = ""
    added: tuple[str, ...] = ()
    removed: tuple[str, ...] = ()
    changed: tuple[str, ...] = ()
    per_item: bool = False          # the collection's items were compared

    def text(self) -> str:
        if not self.per_item:
            return f"input {self.arg} ({self.source}{self.item}) changed"
        bits = [f"{label} {_listed(names)}" for label, names in
                (("added", self.added), ("removed", self.removed), ("changed", self.changed)) if names]
        return f"input {self.arg} ({self.source}): {'; '.join(bits) or 'changed'}"


NEW_TEXT = {"pipeline": "no earlier run of this pipeline", "stage": "new stage", "item": "new item",
            "tile": "new tile (the items in it changed)", "task": "not run before"}
MISSING_TEXT = {"missing": "result missing from the cache (deleted or found corrupt)",
                "corrupt": "result in the cache is damaged (found corrupt)",
                "partial": "its result left out failed items: runs again after they are retried",
                "failed": "failed in the last run: runs again"}


@dataclass(frozen=True)
class Reason:
    """Why a task will run, compared with the last recorded run (after Snakemake's ``Reason``).

    Each field is one component: ``forced`` (the stage was named by ``--force``, or is downstream of one that
    was: recomputed even when cached), ``new`` (nothing recorded: "pipeline", "stage", "item", "tile" or "task"),
    ``missing`` (same key but no usable result: "missing" or "corrupt"), ``function`` ((old, new) name),
    ``code`` (project functions/constants whose fingerprint changed) and ``code_gone`` (no longer used),
    ``params`` ((name, old, new)), ``inputs`` (:class:`InputChange`), ``generated`` (the stage waits for a
    generated dataset that ``run`` writes first; ``detail`` says why it is not usable yet).
    :meth:`text` is the one place a reason becomes words.
    """
    forced: bool = False
    new: str = ""
    missing: str = ""
    function: tuple[str, str] | None = None
    code: tuple[str, ...] = ()
    code_gone: tuple[str, ...] = ()
    code_changed: bool = False
    params: tuple[tuple[str, Any, Any], ...] = ()
    inputs: tuple[InputChange, ...] = ()
    generated: str = ""
    detail: str = ""

    def text(self) -> str:
        if self.forced:
            return "forced"
        if self.generated:
            return f"dataset '{self.generated}' is generated by run first ({self.detail or 'not generated yet'})"
        if self.new:
            return NEW_TEXT[self.new]
        if self.missing:
            return MISSING_TEXT[self.missing]
        why = []
        if self.function is not None:
            why.append(f"function {self.function[0]} -> {self.function[1]}")
        if self.code_changed:
            what = ", ".join(list(self.code) + [f"{g} (no longer used)" for g in self.code_gone]) or "fingerprint"
            why.append(f"code changed: {what}")
        why += [f"param {k}: {_short(a)} -> {_short(b)}" for k, a, b in self.params]
        why += [c.text() for c in self.inputs]
        return "; ".join(why) or "key changed"

    __str__ = text


def _item_suffix(plan: Plan, task: Task, ref) -> str:
    """'[item]' when the input is one item of a collection, '' when it is a single value or a whole collection."""
    if ref is None:
        return ""
    if ref.item is not None:
        return f"[{ref.item}]"
    source = plan.datasets.get(ref.source) or (plan.stages[ref.source].source if ref.source in plan.stages else None)
    per_item = source is not None and source.kind is SourceKind.ITEMS
    if per_item and not ref.whole and plan.stages[task.stage].spec.fanout == "item":
        return f"[{task.label}]"
    return ""


def _input_changes(plan: Plan, task: Task, prev_task: dict, prev_stage: dict) -> tuple[InputChange, ...]:
    sp = plan.stages[task.stage]
    out = []
    for arg, digest in task.input_digests.items():
        if prev_task["inputs"].get(arg) == digest:
            continue
        ref = sp.spec.inputs.get(arg)
        src = ref.source if ref else sp.spec.candidates if arg == "pairs" and sp.spec.candidates else arg
        old_items, new_items = prev_stage.get("input_items", {}).get(arg), sp.input_items.get(arg)
        if old_items is not None and new_items is not None:
            out.append(InputChange(
                arg, src, per_item=True, added=tuple(sorted(set(new_items) - set(old_items))),
                removed=tuple(sorted(set(old_items) - set(new_items))),
                changed=tuple(sorted(k for k in new_items if k in old_items and new_items[k] != old_items[k]))))
        else:
            out.append(InputChange(arg, src, item=_item_suffix(plan, task, ref)))
    return tuple(out)


def _new_kind(task: Task, fanout: str) -> str:
    if task.label and fanout == "item":
        return "item"
    return "tile" if fanout == "pair" else "task"


def explain(task: Task, plan: Plan, record: dict | None) -> Reason:
    """Why ``task`` (a cache miss, or a task of a forced stage) will run, compared with the last recorded run."""
    sp = plan.stages[task.stage]
    if plan.is_forced(task):
        return Reason(forced=True)
    if record is None:
        return Reason(new="pipeline")
    prev_stage = record["stages"].get(task.stage)
    if prev_stage is None:
        return Reason(new="stage")
    prev = prev_stage["tasks"].get(task.label)
    if prev is None:
        return Reason(new=_new_kind(task, sp.spec.fanout))
    if prev["key"] == task.key:
        if plan.store.has(task.key):  # stored, but computed without some failed items
            return Reason(missing="partial")
        failed = {(f.get("stage"), f.get("item")) for f in record.get("summary", {}).get("failures", [])}
        if (task.stage, task.label) in failed:
            return Reason(missing="failed")
        return Reason(missing="corrupt" if plan.store.manifest_exists(task.key) else "missing")
    old_parts, new_parts = prev_stage.get("code_parts", {}), sp.code_parts
    old_params, new_params = prev_stage["params"], sp.spec.params
    return Reason(
        function=(prev_stage["function"], sp.spec.function) if prev_stage["function"] != sp.spec.function else None,
        code_changed=prev_stage["code"] != sp.code,
        code=tuple(sorted(k for k in new_parts if old_parts.get(k) != new_parts[k])),
        code_gone=tuple(sorted(k for k in old_parts if k not in new_parts)),
        params=tuple((k, old_params.get(k, "<unset>"), new_params.get(k, "<unset>"))
                     for k in sorted(set(old_params) | set(new_params))
                     if old_params.get(k, "<unset>") != new_params.get(k, "<unset>")),
        inputs=_input_changes(plan, task, prev, prev_stage))


def pending_reason(plan: Plan, stage: str) -> Reason:
    """Why a stage that waits for a generated dataset (no tasks planned yet) will run."""
    name = plan.stages[stage].pending
    return Reason(generated=name, detail=plan.pending_generated.get(name, ""))


def reason(task: Task, plan: Plan, record: dict | None) -> str:
    """:func:`explain` as text."""
    return explain(task, plan, record).text()
