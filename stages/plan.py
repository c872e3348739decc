"""From a validated pipeline to a task graph with content-addressed keys.

key(task) = hash(function name, code fingerprint, canonical JSON of its declared params, keys of its
inputs). Input keys chain (an upstream task's key stands for its result), so big arrays are never
re-hashed; raw input files are hashed by content, with a (size, mtime) cache so unchanged files are not
read again.
"""
from __future__ import annotations

import glob
import json
import os
import re
import shutil
from dataclasses import dataclass, field
from typing import Any

from . import registry
from .config import DatasetSpec, GeneratedPath, Pipeline, StageSpec
from .errors import PipelineError
from . import fingerprint
from .fingerprint import code_fingerprint
from .store import Store, atomic_write_text, digest_json, file_checksum

KEY_VERSION = 1


# ---------------------------------------------------------------------------------------------
# raw input files
# ---------------------------------------------------------------------------------------------
class FileHasher:
    """Content hashes of input files, cached by (path, size, mtime_ns) in ``cache/filehash.json``."""

    def __init__(self, store: Store):
        self.path = os.path.join(store.root, "filehash.json")
        try:
            with open(self.path, encoding="utf-8") as fh:
                self.table = json.load(fh)
        except (FileNotFoundError, json.JSONDecodeError):
            self.table = {}
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
            atomic_write_text(self.path, json.dumps(self.table))
            self.dirty = False


# ---------------------------------------------------------------------------------------------
# what a stage or dataset offers downstream
# ---------------------------------------------------------------------------------------------
@dataclass
class Source:
    """The result of a dataset or stage as seen by its consumers.

    kind: "value" (one dataset value: a path), "items" (per-item), "entry" (a once stage),
    "pairs" (a pair stage's tiles).
    """
    kind: str
    items: dict[str, dict] = field(default_factory=dict)   # name -> input spec (per item)
    single: dict | None = None                             # input spec of a once value
    pairs: dict | None = None                              # pairs layout spec

    def item_names(self) -> list[str]:
        return list(self.items)


@dataclass
class Task:
    stage: str
    label: str                  # item name, "tile i-j" or "" for once stages
    key: str
    function: str
    params: dict
    inputs: dict[str, dict]     # arg -> input spec for the worker
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


@dataclass
class Plan:
    pipeline: Pipeline
    store: Store
    stages: dict[str, StagePlan]
    datasets: dict[str, Source]

    def tasks(self) -> list[Task]:
        return [t for sp in self.stages.values() for t in sp.tasks]

    def missing(self) -> list[Task]:
        return [t for t in self.tasks() if not self.store.has(t.key)]


def _spec_key(spec: dict) -> Any:
    """The identity of an input spec: what its value depends on."""
    kind = spec["kind"]
    if kind == "entry":
        return spec["key"]
    if kind == "value":
        return spec.get("digest")
    if kind == "dict":
        return {k: _spec_key(v) for k, v in spec["items"].items()}
    if kind == "stack":
        return [_spec_key(v) for v in spec["parts"]]
    if kind == "pairs":
        return {"names": spec["names"], "tiles": spec["tiles"], "mirror": spec["mirror"]}
    raise ValueError(kind)


def _deps_of(spec: dict) -> list[str]:
    kind = spec["kind"]
    if kind == "entry":
        return [spec["key"]]
    if kind in ("dict", "stack"):
        parts = spec["items"].values() if kind == "dict" else spec["parts"]
        return [k for v in parts for k in _deps_of(v)]
    if kind == "pairs":
        return [t[2] for t in spec["tiles"]]
    return []


# ---------------------------------------------------------------------------------------------
# planning
# ---------------------------------------------------------------------------------------------
def build_plan(pipe: Pipeline, log=print) -> Plan:
    """Resolve generated data and datasets, then compute every task and its key (runs nothing else)."""
    store = Store(pipe.cache_dir)
    fingerprint.use_disk_cache(os.path.join(store.root, "fingerprints.json"))
    hasher = FileHasher(store)
    _materialize_generated(pipe, store, log)
    datasets = {name: _dataset_source(pipe, ds, hasher) for name, ds in pipe.datasets.items()}
    hasher.save()
    sources: dict[str, Source] = dict(datasets)
    stages: dict[str, StagePlan] = {}
    for name, spec in pipe.stages.items():
        sp = _plan_stage(pipe, spec, sources)
        stages[name] = sp
        sources[name] = sp.source
    fingerprint.save_disk_cache()
    return Plan(pipe, store, stages, datasets)


def _generated_key(gen) -> str:
    fn = registry.get(gen.generator)
    code, _ = code_fingerprint(fn.func)
    return digest_json({"v": KEY_VERSION, "generator": gen.generator, "code": code, "params": gen.params})


def _materialize_generated(pipe: Pipeline, store: Store, log) -> None:
    """Write each generated dataset once into cache/generated/<key> and substitute its path."""
    for gen in pipe.generated.values():
        key = _generated_key(gen)
        gen.path = os.path.join(store.root, "generated", key)
    used = _generated_names_used(pipe)
    for name in used:
        gen = pipe.generated[name]
        if os.path.exists(os.path.join(gen.path, ".complete")):
            continue
        log(f"generating dataset '{name}' with {gen.generator} {gen.params} -> {gen.path}")
        tmp = store.tmp_dir()
        registry.get(gen.generator).func(out_dir=tmp, **gen.params)
        atomic_write_text(os.path.join(tmp, ".complete"), json.dumps({"generator": gen.generator, "params": gen.params}))
        os.makedirs(os.path.dirname(gen.path), exist_ok=True)
        try:
            os.rename(tmp, gen.path)
        except OSError:
            if not os.path.exists(os.path.join(gen.path, ".complete")):
                raise
            shutil.rmtree(tmp, ignore_errors=True)

    def sub(value):
        if isinstance(value, GeneratedPath) or (isinstance(value, str) and value.startswith("@generated/")):
            gname, _, rest = value[len("@generated/"):].partition("/")
            return os.path.join(pipe.generated[gname].path, rest) if rest else pipe.generated[gname].path
        if isinstance(value, dict):
            return {k: sub(v) for k, v in value.items()}
        if isinstance(value, list):
            return [sub(v) for v in value]
        return value

    pipe.params = sub(pipe.params)
    for ds in pipe.datasets.values():
        ds.path = sub(ds.path)
    for st in pipe.stages.values():
        st.params = sub(st.params)


def _generated_names_used(pipe: Pipeline) -> list[str]:
    found: set[str] = set()

    def scan(value):
        if isinstance(value, str) and value.startswith("@generated/"):
            found.add(value[len("@generated/"):].split("/")[0])
        elif isinstance(value, dict):
            for v in value.values():
                scan(v)
        elif isinstance(value, list):
            for v in value:
                scan(v)

    scan([ds.path for ds in pipe.datasets.values()])
    scan([st.params for st in pipe.stages.values()])
    return sorted(found)


def _dataset_error(pipe: Pipeline, ds: DatasetSpec, msg: str, fix: str) -> PipelineError:
    return PipelineError(msg, file=pipe.file, key=f"datasets.{ds.name}.{ds.kind}", fix=fix)


def _value_spec(value: Any, digest: str) -> dict:
    return {"kind": "value", "value": value, "digest": digest}


def _dataset_source(pipe: Pipeline, ds: DatasetSpec, hasher: FileHasher) -> Source:
    fix = "check the path, or point the pipeline at your data with --set data.root=PATH"
    path = ds.path
    if ds.kind in ("file", "folder"):
        exists = os.path.isfile(path) if ds.kind == "file" else os.path.isdir(path)
        if not exists:
            if ds.optional:
                return Source("value", single=_value_spec(None, "absent"))
            raise _dataset_error(pipe, ds, f"{ds.kind} not found: {path}", fix)
        if ds.kind == "file":
            return Source("value", single=_value_spec(os.path.abspath(path), hasher.digest(path)))
        files = sorted(p for p in glob.glob(os.path.join(path, "**", "*"), recursive=True) if os.path.isfile(p))
        digest = digest_json([[os.path.relpath(p, path), hasher.digest(p)] for p in files])
        return Source("value", single=_value_spec(os.path.abspath(path), digest))
    folder = os.path.dirname(path) or "."
    if not glob.has_magic(folder) and not os.path.isdir(folder):
        if ds.optional:
            return Source("items", items={})
        raise _dataset_error(pipe, ds, f"folder not found: {folder}", fix)
    files = sorted(p for p in glob.glob(path) if os.path.isfile(p))
    items: dict[str, dict] = {}
    if ds.kind == "files":
        for p in files:
            name = os.path.splitext(os.path.basename(p))[0]
            if name in items:
                raise _dataset_error(pipe, ds, f"two files give the item name '{name}': {items[name]['value']} and {p}",
                                     "make the glob narrower or rename one file")
            items[name] = _value_spec(os.path.abspath(p), hasher.digest(p))
    else:
        groups: dict[str, dict[int, str]] = {}
        rx = re.compile(ds.pattern)
        for p in files:
            m = rx.fullmatch(os.path.basename(p))
            if m:
                idx = m.groupdict().get("index")
                idx = 0 if idx is None else int(idx) if idx.isdigit() else idx
                group = groups.setdefault(m.group("item"), {})
                if idx in group:
                    raise _dataset_error(pipe, ds, f"item '{m.group('item')}' has two files for part {idx}: "
                                         f"{group[idx]} and {p}", "keep one of them")
                group[idx] = os.path.abspath(p)
        counts = [len(g) for g in groups.values()]
        expected = max(counts) if counts else 0
        for name in sorted(groups):
            g = groups[name]
            if all(isinstance(k, int) for k in g) and expected > 1 and sorted(g) != list(range(expected)):
                missing = sorted(set(range(expected)) - set(g))
                raise _dataset_error(pipe, ds, f"item '{name}' is missing parts {missing} "
                                     f"(other items have {expected}: 0..{expected - 1})",
                                     f"add the missing files for '{name}' or remove its files")
            paths = [g[k] for k in sorted(g)]
            items[name] = _value_spec(paths, digest_json([hasher.digest(p) for p in paths]))
    if not items and not ds.optional:
        raise _dataset_error(pipe, ds, f"no files match {path}", fix)
    return Source("items", items=dict(sorted(items.items())))


def _task_key(function: str, code: str, params: dict, input_ids: dict, item_name: str | None) -> str:
    return digest_json({"v": KEY_VERSION, "function": function, "code": code, "params": params,
                        "inputs": input_ids, "item": item_name})


def _resolve_input(stage: StageSpec, arg: str, ref, sources: dict[str, Source], item: str | None,
                   pipe: Pipeline) -> dict:
    src = sources[ref.source]
    where = f"stages.{stage.name}.inputs.{arg}"
    if src.kind in ("value", "entry"):
        return src.single
    if src.kind == "pairs":
        return src.pairs
    if ref.item is not None:
        if ref.item not in src.items:
            raise PipelineError(f"'{ref.source}' has no item '{ref.item}'", file=pipe.file, key=where,
                                fix=f"items: {', '.join(list(src.items)[:10])}{' ...' if len(src.items) > 10 else ''}")
        return src.items[ref.item]
    if item is not None and not ref.whole:
        if item not in src.items:
            raise PipelineError(f"'{ref.source}' has no item '{item}' (stage '{stage.name}' runs per item of "
                                f"'{stage.over}')", file=pipe.file, key=where,
                                fix=f"use '{ref.source}[*]' to pass the whole collection")
        return src.items[item]
    return {"kind": "dict", "items": dict(src.items)}


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


def _plan_stage(pipe: Pipeline, spec: StageSpec, sources: dict[str, Source]) -> StagePlan:
    fn = registry.get(spec.function)
    code, parts = code_fingerprint(fn.func)
    if fn.mirror is not None:
        mcode, mparts = code_fingerprint(fn.mirror)
        parts.update(mparts)
        code = digest_json([code, mcode])
    tasks: list[Task] = []

    def add_task(label: str, inputs: dict[str, dict], item_name: str | None):
        ids = {arg: _spec_key(s) for arg, s in inputs.items()}
        key = _task_key(spec.function, code, spec.params, ids, item_name if "item_name" in fn.engine_args else None)
        deps = sorted({k for s in inputs.values() for k in _deps_of(s)})
        digests = {arg: digest_json(i) for arg, i in ids.items()}
        tasks.append(Task(spec.name, label, key, spec.function, spec.params, inputs, deps, digests, item_name))
        return key

    input_items: dict[str, dict[str, str]] = {}
    if spec.fanout == "item":
        over = sources[spec.over]
        if over.kind != "items":
            raise PipelineError(f"cannot run per item of '{spec.over}': it is not a collection",
                                file=pipe.file, key=f"stages.{spec.name}.foreach",
                                fix="foreach takes a files/groups dataset or a per-item stage")
        out = {}
        for item in over.items:
            inputs = {arg: _resolve_input(spec, arg, ref, sources, item, pipe) for arg, ref in spec.inputs.items()}
            out[item] = {"kind": "entry", "key": add_task(item, inputs, item)}
        source = Source("items", items=out)
    elif spec.fanout == "pair":
        over = sources[spec.over]
        if over.kind != "items":
            raise PipelineError(f"cannot pair the items of '{spec.over}': it is not a collection",
                                file=pipe.file, key=f"stages.{spec.name}.pairs")
        names = list(over.items)
        blocks = make_blocks(names, spec.tile)
        tiles = []
        for bi, (s0, e0) in enumerate(blocks):
            for bj in range(bi, len(blocks)):
                s1, e1 = blocks[bj]
                a = {"kind": "stack", "parts": [over.items[n] for n in names[s0:e0]]}
                b = {"kind": "stack", "parts": [over.items[n] for n in names[s1:e1]]}
                key = add_task(f"tile {names[s0]}..{names[e0 - 1]} x {names[s1]}..{names[e1 - 1]}",
                               {"A": a, "B": b}, None)
                tiles.append([bi, bj, key])
        source = Source("pairs", pairs={"kind": "pairs", "names": names, "blocks": [list(b) for b in blocks],
                                        "tiles": tiles, "mirror": spec.function})
    else:
        inputs = {arg: _resolve_input(spec, arg, ref, sources, None, pipe) for arg, ref in spec.inputs.items()}
        for arg, s in inputs.items():
            if s["kind"] == "dict":
                input_items[arg] = {k: json.dumps(_spec_key(v)) for k, v in s["items"].items()}
        key = add_task("", inputs, None)
        source = Source("entry", single={"kind": "entry", "key": key})
    return StagePlan(spec, code, parts, tasks, source, input_items)
