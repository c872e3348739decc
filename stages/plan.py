"""From a validated pipeline to a task graph with content-addressed keys; planning runs and writes nothing.

key(task) = hash(function name, code fingerprint, canonical JSON of its declared params, keys of its
inputs). Input keys chain (an upstream task's key stands for its result), so big arrays are never
re-hashed; raw input files are hashed by content, with a (size, mtime) cache so unchanged files are not
read again. The caches (input file hashes, code fingerprints) are written by ``run`` only
(:meth:`Plan.save_caches`); stages that read a generated dataset not written yet are planned without tasks
(``StagePlan.pending``) until ``run`` has generated it. Likewise a pair stage on a candidate graph
(``candidates: STAGE``) and the stages downstream of it wait (``StagePlan.waiting``) until STAGE's result is in
the cache: its tasks are the candidate pairs that result names (``run`` executes in rounds, planning again
when such a result lands, like Snakemake's checkpoints).
"""
from __future__ import annotations

import enum
import json
import glob
import os
import re
from dataclasses import dataclass, field

import numpy as np

from . import fingerprint, registry, select
from .cache import open_store
from .candidates import CANDIDATES_FORMAT, candidate_pairs
from .checksums import digest_bytes, digest_json, file_checksum, read_checked_json, write_checked_json
from .config import DatasetSpec, GeneratedPath, InputRef, Pipeline, StageSpec, load_pipeline
from .errors import CorruptEntry, PipelineError, warn_once
from .fingerprint import code_fingerprint
from .generated import resolve_generated
from .inputs import (DictInput, EntryInput, IndexPairsInput, InputSpec, PairsInput, SparsePairsInput, StackInput,
                     ValueInput)
from .store import Store, left_out_of

KEY_VERSION = 1


# ---------------------------------------------------------------------------------------------
# raw input files
# ---------------------------------------------------------------------------------------------
class FileHasher:
    """Content hashes of input files, cached by (path, size, mtime_ns) in ``cache/filehash.json``."""

    def __init__(self, store: Store):
        self.path = os.path.join(store.root, "filehash.json")
        table = read_checked_json(self.path, "rehashing the input files", default={})
        # rows that are not [size, mtime_ns, digest] are dropped (the file is hashed again)
        self.table = {p: r for p, r in table.items() if isinstance(r, list) and len(r) == 3}
        self.dirty = False

    def digest(self, path: str) -> str:
        path = os.path.abspath(path)
        st = os.stat(path)
        rec = self.table.get(path)
        if rec and rec[0] == st.st_size and rec[1] == st.st_mtime_ns:
            return rec[2]
        digest = file_checksum(path)
        self.table[path] = [st.st_size, st.st_mtime_ns, digest]
        self.dirty = True
        return digest

    def save(self) -> None:
        if self.dirty:
            try:
                write_checked_json(self.path, self.table)
            except OSError:  # a read-only cache: the hashes are only a speed-up
                pass
            self.dirty = False


# ---------------------------------------------------------------------------------------------
# what a stage or dataset offers downstream
# ---------------------------------------------------------------------------------------------
class SourceKind(enum.Enum):
    """The shape of what a dataset or stage offers its consumers."""
    VALUE = "value"      # one dataset value (a path)
    ITEMS = "items"      # one input per item (a files/groups dataset, a per-item stage)
    ENTRY = "entry"      # the result of a once stage
    PAIRS = "pairs"      # the tiles of a pair stage
    PENDING = "pending"  # not known until a generated dataset is written (by run)
    WAITING = "waiting"  # not known until a candidates stage's result is in the cache (run plans again then)
    SKIPPED = "skipped"  # nothing to offer: an optional dataset that is absent or empty, or a skipped stage


@dataclass
class Source:
    """The result of a dataset or stage as seen by its consumers (see :class:`SourceKind`)."""
    kind: SourceKind
    items: dict[str, InputSpec] = field(default_factory=dict)   # ITEMS: item name -> input
    single: InputSpec | None = None                             # VALUE, ENTRY
    pairs: PairsInput | SparsePairsInput | None = None          # PAIRS (complete, or on a candidate graph)
    pending: str | None = None                                  # PENDING: the generated dataset waited for
    waiting: str | None = None                                  # WAITING: the candidates stage waited for
    waiting_detail: str = ""                                    # WAITING: why its result is not usable yet
    skipped: str | None = None                                  # SKIPPED: why (shown by run and status)

    def item_names(self) -> list[str]:
        return list(self.items)


@dataclass
class Task:
    """One unit of work: a function call on inputs, identified by its content-addressed ``key``."""
    stage: str
    label: str                  # item name, "tile i-j" or "" for once stages
    key: str
    function: str
    params: dict
    inputs: dict[str, InputSpec]  # arg -> what the worker loads for it
    deps: list[str]             # keys of upstream tasks
    input_digests: dict[str, str]
    item_name: str | None = None

    @property
    def display(self) -> str:
        return f"{self.stage}[{self.label}]" if self.label else self.stage


@dataclass
class StagePlan:
    spec: StageSpec
    code: str
    code_parts: dict[str, str]
    tasks: list[Task]
    source: Source
    input_items: dict[str, dict[str, str]] = field(default_factory=dict)
    pending: str | None = None  # a generated dataset this stage needs and run has not written yet (no tasks)
    skipped: str | None = None  # why this stage has no tasks: an input it needs is absent (see SourceKind.SKIPPED)
    waiting: str | None = None  # the candidates stage whose result is not in the cache yet (no tasks until it is)
    waiting_detail: str = ""    # why that result is not usable yet ("not computed yet", or that it is damaged)


@dataclass
class Plan:
    pipeline: Pipeline          # with the paths of the generated datasets filled in (those written)
    store: Store
    stages: dict[str, StagePlan]
    datasets: dict[str, Source]
    pending_generated: dict[str, str] = field(default_factory=dict)  # name -> why it is not usable yet
    hasher: "FileHasher | None" = None
    damaged_candidates: dict[str, str] = field(default_factory=dict)  # key -> error: stored but unreadable
    forced: frozenset[str] = frozenset()    # stages recomputed even when cached (--force, see stages.select)
    recomputed: set[str] = field(default_factory=set)  # keys of forced tasks this run has stored (run once)
    untargeted: tuple[str, ...] = ()        # stages of the pipeline file left out: the targets do not need them

    def waiting(self) -> dict[str, str]:
        """{candidates stage: its task key} for every candidates stage some stage waits for."""
        names = {sp.waiting for sp in self.stages.values() if sp.waiting is not None}
        return {n: self.stages[n].tasks[0].key for n in sorted(names) if self.stages[n].tasks}

    def tasks(self) -> list[Task]:
        return [t for sp in self.stages.values() for t in sp.tasks]

    def missing(self) -> list[Task]:
        """Tasks without a usable result, tasks whose result left out failed items (they run again after
        those items are retried: cached at once if the same items fail, recomputed if they now succeed), and
        the tasks of forced stages this run has not recomputed yet."""
        return list(self._missing())

    def _missing(self):
        return (t for t in self.tasks() if self.is_forced(t) or _incomplete(self.store.complete(t.key)))

    def is_forced(self, task: Task) -> bool:
        """True when ``task`` belongs to a forced stage and this run has not stored it yet."""
        return task.stage in self.forced and task.key not in self.recomputed

    def again(self) -> "Plan":
        """The same pipeline planned again (after a round stored results, or entries were invalidated), with the
        same targets and forced stages and what this run has already recomputed."""
        plan = build_plan(self.pipeline)
        plan.forced, plan.recomputed, plan.untargeted = self.forced, self.recomputed, self.untargeted
        return plan

    def save_caches(self) -> None:
        """Write the input-file hashes and code fingerprints computed while planning (``run`` does)."""
        if self.hasher is not None:
            self.hasher.save()
        fingerprint.save_disk_cache()


# ---------------------------------------------------------------------------------------------
# planning
# ---------------------------------------------------------------------------------------------
def build_plan(pipe: Pipeline) -> Plan:
    """Resolve generated data and datasets, then compute every task and its key. Reads only: runs no
    generator and writes no file (not even the caches; see :meth:`Plan.save_caches`); planning prints nothing
    (problems are errors or one-time warnings)."""
    store = open_store(pipe.cache_dir)  # not claimed here: planning writes nothing (run.prepare claims it)
    fingerprint.use_disk_cache(os.path.join(store.root, "fingerprints.json"))
    hasher = FileHasher(store)
    pipe, pending = resolve_generated(pipe, store, hasher.digest)
    datasets = {name: _dataset_source(pipe, ds, hasher) for name, ds in pipe.datasets.items()}
    sources: dict[str, Source] = dict(datasets)
    stages: dict[str, StagePlan] = {}
    damaged: dict[str, str] = {}
    for name, spec in pipe.stages.items():
        sp = _plan_stage(pipe, spec, sources, store, damaged)
        stages[name] = sp
        sources[name] = sp.source
    return Plan(pipe, store, stages, datasets, pending, hasher, damaged)


def _incomplete(manifest: dict | None) -> bool:
    """True when a stored result must be computed (again): there is none, or it left out failed items."""
    return manifest is None or any(e[0] for e in left_out_of(manifest))


def plan_pipeline(path: str, overrides=(), cache_dir=None, output_dir=None, quiet=False, targets=(),
                  force=()) -> Plan:
    """Read and validate the pipeline file ``path`` (with ``--set`` overrides) and plan it (``quiet`` is
    accepted for symmetry with the commands; planning prints nothing).

    ``targets``: stage names; only they and the stages they need are planned (all stages when empty).
    ``force``: stage names recomputed even when cached, with their downstream stages (see stages.select).
    """
    full = load_pipeline(path, overrides, cache_dir=cache_dir, output_dir=output_dir)
    pipe = select.only(full, targets)
    forced = select.forced(pipe, force, full)
    plan = build_plan(pipe)
    plan.forced = forced
    plan.untargeted = tuple(n for n in full.stages if n not in pipe.stages)
    return plan


def _dataset_error(pipe: Pipeline, ds: DatasetSpec, msg: str, fix: str) -> PipelineError:
    return PipelineError(msg, file=pipe.file, key=f"datasets.{ds.name}.{ds.kind}", fix=fix)


def _dataset_source(pipe: Pipeline, ds: DatasetSpec, hasher: FileHasher) -> Source:
    """What dataset ``ds`` offers: one value (file, folder) or items (files, groups), hashed by content;
    pending when its path lies in a generated dataset not written yet."""
    if isinstance(ds.path, GeneratedPath):
        return Source(SourceKind.PENDING, pending=ds.path.generated_name)
    fix = "check the path, or point the pipeline at your data with --set data.root=PATH"
    path = ds.path
    if ds.kind in ("file", "folder"):
        exists = os.path.isfile(path) if ds.kind == "file" else os.path.isdir(path)
        if not exists:
            if ds.optional:
                return Source(SourceKind.VALUE, single=ValueInput(None, "absent"))
            raise _dataset_error(pipe, ds, f"{ds.kind} not found: {path}", fix)
        if ds.kind == "file":
            return Source(SourceKind.VALUE, single=ValueInput(os.path.abspath(path), hasher.digest(path)))
        files = sorted(p for p in glob.glob(os.path.join(path, "**", "*"), recursive=True) if os.path.isfile(p))
        digest = digest_json([[os.path.relpath(p, path), hasher.digest(p)] for p in files])
        return Source(SourceKind.VALUE, single=ValueInput(os.path.abspath(path), digest))
    if ds.optional and not path:
        return Source(SourceKind.SKIPPED, skipped=f"optional dataset '{ds.name}' is not given (its path is empty)")
    folder = os.path.dirname(path) or "."
    if not glob.has_magic(folder) and not os.path.isdir(folder):
        if ds.optional:
            return Source(SourceKind.SKIPPED, skipped=f"optional dataset '{ds.name}' is absent ({folder} not found)")
        raise _dataset_error(pipe, ds, f"folder not found: {folder}", fix)
    files = sorted(p for p in glob.glob(_any_case_extension(path) if ds.kind == "files" else path)
                   if os.path.isfile(p))
    items: dict[str, ValueInput] = {}
    if ds.kind == "files":
        for p in files:
            name = os.path.splitext(os.path.basename(p))[0]
            if name in items:
                raise _dataset_error(pipe, ds, f"two files give the item name '{name}': {items[name].value} and {p}",
                                     "make the glob narrower or rename one file")
            items[name] = ValueInput(os.path.abspath(p), hasher.digest(p))
    else:
        groups: dict[str, dict[int, str]] = {}
        rx = re.compile(ds.pattern)
        unmatched = []
        for p in files:
            m = _match_name(rx, os.path.basename(p))
            if m is None and _looks_like_data(os.path.basename(p), ds.pattern):
                unmatched.append(os.path.basename(p))
            if m:
                idx = m.groupdict().get("index")
                idx = 0 if idx is None else int(idx) if idx.isdigit() else idx
                group = groups.setdefault(m.group("item"), {})
                if idx in group:
                    raise _dataset_error(pipe, ds, f"item '{m.group('item')}' has two files for part {idx}: "
                                         f"{group[idx]} and {p}", "keep one of them")
                group[idx] = os.path.abspath(p)
        if unmatched:
            shown = ", ".join(unmatched[:6]) + (f" ... (+{len(unmatched) - 6})" if len(unmatched) > 6 else "")
            warn_once(f"dataset '{ds.name}': {len(unmatched)} file(s) in {os.path.dirname(path) or '.'} do not match "
                      f"its pattern and are not used: {shown} (pattern {ds.pattern}; rename them, e.g. NAME.obj or "
                      f"NAME_V.png, or change 'pattern:')")
        counts = [len(g) for g in groups.values()]
        expected = max(counts) if counts else 0
        for name in sorted(groups):
            g = groups[name]
            paths = [g[k] for k in sorted(g)]
            error = ""
            if all(isinstance(k, int) for k in g) and expected > 1 and sorted(g) != list(range(expected)):
                missing = sorted(set(range(expected)) - set(g))  # an item failure of this item, not the pipeline's
                error = (f"{os.path.dirname(paths[0])}: item '{name}' is missing parts {missing} (other items have "
                         f"{expected}: 0..{expected - 1}); add the missing files for '{name}' or remove its files")
            items[name] = ValueInput(paths, digest_json([hasher.digest(p) for p in paths]), error)
    if not items and not ds.optional:
        raise _dataset_error(pipe, ds, f"no files match {path}", fix)
    if not items:
        return Source(SourceKind.SKIPPED, skipped=f"optional dataset '{ds.name}' is empty (no files match {path})")
    return Source(SourceKind.ITEMS, items=dict(sorted(items.items())))


def _any_case_extension(path: str) -> str:
    """A glob whose literal file extension also matches in upper or mixed case: ``d/*.obj`` -> ``d/*.[oO][bB][jJ]``."""
    folder, base = os.path.split(path)
    m = re.fullmatch(r"(.*\.)([A-Za-z0-9]+)", base)
    if not m:
        return path
    ext = "".join(f"[{c.lower()}{c.upper()}]" if c.isalpha() else c for c in m.group(2))
    return os.path.join(folder, m.group(1) + ext)


def _match_name(rx: re.Pattern, name: str) -> re.Match | None:
    """``rx`` matched against a file name, also with its extension in lower case (``UPPER.OBJ``)."""
    m = rx.fullmatch(name)
    if m is None:
        stem, ext = os.path.splitext(name)
        if ext != ext.lower():
            m = rx.fullmatch(stem + ext.lower())
    return m


def _looks_like_data(name: str, pattern: str) -> bool:
    """True when the file's extension is one the pattern names (a data file whose name does not fit)."""
    ext = os.path.splitext(name)[1][1:].lower()
    return bool(ext) and re.search(rf"(?<![A-Za-z0-9]){re.escape(ext)}(?![A-Za-z0-9])", pattern, re.I) is not None


def _task_key(function: str, code: str, params: dict, input_ids: dict, item_name: str | None) -> str:
    return digest_json({"v": KEY_VERSION, "function": function, "code": code, "params": params,
                        "inputs": input_ids, "item": item_name})


def _resolve_input(stage: StageSpec, arg: str, ref: InputRef, sources: dict[str, Source], item: str | None,
                   pipe: Pipeline) -> InputSpec:
    """The input spec of argument ``arg`` (wired to ``ref``) for one task of ``stage`` (``item``: its item)."""
    src = sources[ref.source]
    where = f"stages.{stage.name}.inputs.{arg}"
    if src.kind is SourceKind.SKIPPED:  # an optional input (see _skipped_of): the function's default None
        return ValueInput(None, "skipped")
    if src.kind in (SourceKind.VALUE, SourceKind.ENTRY):
        return src.single
    if src.kind is SourceKind.PAIRS:
        return src.pairs
    if ref.item is not None:
        if ref.item not in src.items:
            items = f"{', '.join(list(src.items)[:10])}{' ...' if len(src.items) > 10 else ''}"
            if ref.item_param:      # the item name comes from a parameter: name the key to set
                raise PipelineError(f"'{ref.source}' has no item '{ref.item}' (parameter '{ref.item_param}')",
                                    file=pipe.file, key=where,
                                    fix=f"set it to one of the items with --set {ref.item_param}=NAME; items: {items}")
            raise PipelineError(f"'{ref.source}' has no item '{ref.item}'", file=pipe.file, key=where,
                                fix=f"items: {items}")
        return src.items[ref.item]
    if item is not None and not ref.whole:
        if item not in src.items:
            raise PipelineError(f"'{ref.source}' has no item '{item}' (stage '{stage.name}' runs per item of "
                                f"'{stage.over}')", file=pipe.file, key=where,
                                fix=f"use '{ref.source}[*]' to pass the whole collection")
        return src.items[item]
    return DictInput(dict(src.items))


def make_blocks(names: list[str], tile: int) -> list[tuple[int, int]]:
    """Split sorted item names into blocks of about ``tile`` items with content-defined boundaries.

    A block ends after an item whose name hashes to 0 mod ``tile`` (or when it reaches 2*tile items),
    so adding or removing one item changes only the block that holds it, not every block after it.
    Returns [(start, end)] half-open ranges.
    """
    blocks, start = [], 0
    for i, name in enumerate(names):
        size = i - start + 1
        if int(digest_json(name)[:8], 16) % tile == 0 or size >= 2 * tile:
            blocks.append((start, i + 1))
            start = i + 1
    if start < len(names):
        blocks.append((start, len(names)))
    return blocks


def _refs(spec: StageSpec) -> list[InputRef]:
    """Every source ``spec`` reads: its inputs, what it runs over and its candidates stage."""
    return [*spec.inputs.values(), *([InputRef(spec.over)] if spec.over else []),
            *([InputRef(spec.candidates)] if spec.candidates else [])]


def _pending_of(spec: StageSpec, sources: dict[str, Source]) -> str | None:
    """The generated dataset (not written yet) that ``spec`` waits for, through its inputs or params."""
    for ref in _refs(spec):
        if sources[ref.source].kind is SourceKind.PENDING:
            return sources[ref.source].pending
    stack = list(spec.params.values())
    while stack:
        v = stack.pop()
        if isinstance(v, GeneratedPath):
            return v.generated_name
        stack.extend(v.values() if isinstance(v, dict) else v if isinstance(v, list) else [])
    return None


def _skipped_of(spec: StageSpec, fn: registry.StageFunction, sources: dict[str, Source]) -> str | None:
    """Why ``spec`` cannot run, when what it runs over or a required input is skipped (an optional dataset
    that is absent or empty, or a stage skipped for that reason); None when it can. An optional input of the
    function (``other=None``) wired to a skipped source is passed as None instead."""
    for over in (spec.over, spec.candidates):
        if over is not None and sources[over].kind is SourceKind.SKIPPED:
            return sources[over].skipped  # the root cause (a skipped stage passes its own on)
    for arg, ref in spec.inputs.items():
        src = sources[ref.source]
        if src.kind is SourceKind.SKIPPED and arg not in fn.optional_inputs:
            return src.skipped
    return None


def _stage_code(fn: registry.StageFunction) -> tuple[str, dict[str, str]]:
    """The code fingerprint of a stage function (and of its mirror) and its parts."""
    packages = registry.fingerprint_packages()
    code, parts = code_fingerprint(fn.func, packages)
    if fn.mirror is not None:
        mcode, mparts = code_fingerprint(fn.mirror, packages)
        parts.update(mparts)
        code = digest_json([code, mcode])
    return code, parts


def _waiting_of(spec: StageSpec, sources: dict[str, Source]) -> tuple[str, str] | None:
    """(candidates stage, detail) when ``spec`` reads a stage that waits for a candidates stage's result."""
    for ref in _refs(spec):
        src = sources[ref.source]
        if src.kind is SourceKind.WAITING:
            return src.waiting, src.waiting_detail
    return None


def _plan_stage(pipe: Pipeline, spec: StageSpec, sources: dict[str, Source], store: Store,
                damaged: dict[str, str]) -> StagePlan:
    fn = registry.get(spec.function)
    code, parts = _stage_code(fn)
    pending = _pending_of(spec, sources)
    if pending is not None:
        return StagePlan(spec, code, parts, [], Source(SourceKind.PENDING, pending=pending), {}, pending)
    skipped = _skipped_of(spec, fn, sources)
    if skipped is not None:
        return StagePlan(spec, code, parts, [], Source(SourceKind.SKIPPED, skipped=skipped), {}, skipped=skipped)
    waiting = _waiting_of(spec, sources)
    candidates = None
    if waiting is None and spec.candidates is not None:
        candidates, detail = _read_candidates(pipe, spec, sources, store, damaged)
        waiting = None if candidates is not None else (spec.candidates, detail)
    if waiting is not None:  # planned once run has computed the candidates stage
        source = Source(SourceKind.WAITING, waiting=waiting[0], waiting_detail=waiting[1])
        return StagePlan(spec, code, parts, [], source, {}, waiting=waiting[0], waiting_detail=waiting[1])
    tasks: list[Task] = []

    def add_task(label: str, inputs: dict[str, InputSpec], item_name: str | None) -> str:
        ids = {arg: s.key() for arg, s in inputs.items()}
        key = _task_key(spec.function, code, spec.params, ids, item_name if "item_name" in fn.engine_args else None)
        deps = sorted({k for s in inputs.values() for k in s.deps()})
        digests = {arg: digest_json(i) for arg, i in ids.items()}
        tasks.append(Task(spec.name, label, key, spec.function, spec.params, inputs, deps, digests, item_name))
        return key

    input_items: dict[str, dict[str, str]] = {}
    if spec.fanout == "item":
        over = sources[spec.over]
        if over.kind is not SourceKind.ITEMS:
            raise PipelineError(f"cannot run per item of '{spec.over}': it is not a collection",
                                file=pipe.file, key=f"stages.{spec.name}.foreach",
                                fix="foreach takes a files/groups dataset or a per-item stage")
        out: dict[str, InputSpec] = {}
        for item in over.items:
            inputs = {arg: _resolve_input(spec, arg, ref, sources, item, pipe) for arg, ref in spec.inputs.items()}
            out[item] = EntryInput(add_task(item, inputs, item))
        source = Source(SourceKind.ITEMS, items=out)
    elif spec.fanout == "pair" and candidates is not None:
        source = _plan_candidate_pairs(pipe, spec, sources, candidates, add_task)
    elif spec.fanout == "pair":
        over = sources[spec.over]
        if over.kind is not SourceKind.ITEMS:
            raise PipelineError(f"cannot pair the items of '{spec.over}': it is not a collection",
                                file=pipe.file, key=f"stages.{spec.name}.pairs")
        names = list(over.items)
        blocks = make_blocks(names, spec.tile)
        tiles = []
        for bi, (s0, e0) in enumerate(blocks):
            for bj in range(bi, len(blocks)):
                s1, e1 = blocks[bj]
                a = StackInput(tuple(over.items[n] for n in names[s0:e0]))
                b = StackInput(tuple(over.items[n] for n in names[s1:e1]))
                key = add_task(f"tile {names[s0]}..{names[e0 - 1]} x {names[s1]}..{names[e1 - 1]}",
                               {"A": a, "B": b}, None)
                tiles.append((bi, bj, key))
        source = Source(SourceKind.PAIRS, pairs=PairsInput(tuple(names), tuple(blocks), tuple(tiles), spec.function))
    else:
        inputs = {arg: _resolve_input(spec, arg, ref, sources, None, pipe) for arg, ref in spec.inputs.items()}
        for arg, s in inputs.items():
            if isinstance(s, DictInput):
                input_items[arg] = {k: canonical_key(v) for k, v in s.items.items()}
        source = Source(SourceKind.ENTRY, single=EntryInput(add_task("", inputs, None)))
    return StagePlan(spec, code, parts, tasks, source, input_items)


def canonical_key(spec: InputSpec) -> str:
    """An input's identity as JSON text (recorded per item, to name which items of a collection changed)."""
    return json.dumps(spec.key())


# ---------------------------------------------------------------------------------------------
# pair stages on a candidate graph (``candidates: STAGE``)
# ---------------------------------------------------------------------------------------------
def _read_candidates(pipe: Pipeline, spec: StageSpec, sources: dict[str, Source], store: Store,
                     damaged: dict[str, str]) -> tuple[tuple[str, np.ndarray] | None, str]:
    """((candidates key, (P, 2) int64 global pairs), "") when the candidates stage's result is in the cache,
    else (None, why not). A stored result that cannot be read is recorded in ``damaged`` (run recomputes it)."""
    src = sources[spec.candidates]
    if src.kind is not SourceKind.ENTRY:
        raise PipelineError(f"'{spec.candidates}' does not run once, so it cannot give the candidate pairs",
                            file=pipe.file, key=f"stages.{spec.name}.candidates",
                            fix=f"name a once stage returning {CANDIDATES_FORMAT}")
    over = sources[spec.over]
    if over.kind is not SourceKind.ITEMS:
        raise PipelineError(f"cannot pair the items of '{spec.over}': it is not a collection",
                            file=pipe.file, key=f"stages.{spec.name}.pairs")
    key = src.single.entry
    if not store.has(key):
        return None, "not computed yet"
    try:
        value = store.get(key)
    except CorruptEntry as exc:
        damaged[key] = str(exc)
        return None, "its stored result is damaged; run recomputes it"
    try:
        pairs = candidate_pairs(value, list(over.items), spec.over)
    except ValueError as exc:
        cand_fn = pipe.stages[spec.candidates].function
        raise PipelineError(f"stage '{spec.candidates}' ({cand_fn}) returned unusable candidate pairs for the pair "
                            f"stage '{spec.name}': {exc}", file=pipe.file, key=f"stages.{spec.name}.candidates",
                            fix=f"make {cand_fn} return {CANDIDATES_FORMAT}") from None
    return (key, pairs), ""


def _index_digest(pairs: np.ndarray) -> str:
    return digest_bytes(np.ascontiguousarray(pairs, dtype="<i8").tobytes())


def _plan_candidate_pairs(pipe: Pipeline, spec: StageSpec, sources: dict[str, Source],
                          candidates: tuple[str, np.ndarray], add_task) -> Source:
    """The tasks of a pair stage on a candidate graph: the pairs grouped by the block (make_blocks) of their
    first item; per block one task with A = the distinct first items, B = the distinct partners and the local
    index pairs. A task's key depends only on its items and its pairs."""
    cand_key, pairs = candidates
    over = sources[spec.over]
    names = list(over.items)
    tasks = []
    for s0, e0 in make_blocks(names, spec.tile):
        r0, r1 = (int(r) for r in np.searchsorted(pairs[:, 0], [s0, e0]))
        if r0 == r1:
            continue
        mine = pairs[r0:r1]
        a_idx, b_idx = np.unique(mine[:, 0]), np.unique(mine[:, 1])
        local = np.stack([np.searchsorted(a_idx, mine[:, 0]), np.searchsorted(b_idx, mine[:, 1])], axis=1)
        local = local.astype(np.int64)
        inputs = {"A": StackInput(tuple(over.items[names[i]] for i in a_idx)),
                  "B": StackInput(tuple(over.items[names[i]] for i in b_idx)),
                  "pairs": IndexPairsInput(local, _index_digest(local))}
        tasks.append((r0, r1, add_task(f"pairs {names[s0]}..{names[e0 - 1]}", inputs, None)))
    return Source(SourceKind.PAIRS, pairs=SparsePairsInput(tuple(names), pairs, tuple(tasks), cand_key,
                                                           _index_digest(pairs), spec.function))
