"""What runs on a dask worker: load a task's inputs from the store, call the function, store the result.

A task never raises to dask: it returns a :class:`TaskResult`, so one failing item is reported with its
name while the others finish, and dependents of a failed task are skipped rather than crashed.
"""
from __future__ import annotations

import enum
import os
import shutil
import sys
import time
import traceback
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from . import audit, registry
from .cache import open_store
from .errors import CorruptEntry
from .inputs import (DictInput, InputError, InputSpec, PairsInput, SparsePairsInput, StackInput, ValueInput,
                     partial_pairs, partial_tile)
from .logs import configure_logging
from .skipped import Skipped
from .store import Store, left_out_of


class TaskStatus(enum.Enum):
    """What happened to one task."""
    OK = "ok"              # executed and stored
    CACHED = "cached"      # already stored (by another run, meanwhile)
    FAILED = "failed"      # the function raised, or its result cannot be stored
    SKIPPED = "skipped"    # an upstream task did not succeed
    CORRUPT = "corrupt"    # an input entry failed its checksum: the client invalidates and recomputes it

    @property
    def succeeded(self) -> bool:
        return self in (TaskStatus.OK, TaskStatus.CACHED)


@dataclass(frozen=True)
class TaskCall:
    """Everything a worker needs to execute one task (sent to it by the executor)."""
    key: str
    stage: str
    label: str
    function: str
    params: dict
    inputs: dict[str, InputSpec]
    item_name: str | None
    cache: str                  # the store's root folder
    display: str                # "stage[label]"
    force: bool = False         # recompute and replace the stored result even when it is there (--force)


@dataclass(frozen=True)
class TaskResult:
    """The outcome of one task: its status and, when it did not succeed, why."""
    key: str
    stage: str
    label: str
    status: TaskStatus
    display: str = ""
    seconds: float = 0.0        # time spent in the function
    error: str = ""             # FAILED / CORRUPT: one line naming the problem
    traceback: str = ""         # FAILED: the function's traceback
    because: str = ""           # SKIPPED: the upstream task that did not succeed
    corrupt_key: str = ""       # CORRUPT: the input entry to recompute
    left_out: tuple[tuple[str, str, str, str], ...] = ()  # OK/CACHED: items computed without (left_out_items)
    item_skipped: str = ""      # OK: the function returned ``Skipped(why)``: why

    def with_status(self, status: TaskStatus, **changes: Any) -> "TaskResult":
        return replace(self, status=status, **changes)


def load_inputs(store: Store, inputs: dict[str, InputSpec], upstream: tuple = ()) -> dict[str, Any]:
    """The values the function receives for each input argument (CorruptEntry when an entry is damaged).

    upstream: the results of the upstream tasks run with this one. The items of a collection input (dict,
    stack) whose upstream task did not succeed are left out (a stack that keeps none is None); a pairs input
    leaves out the items its tiles were computed without (see left_out_items)."""
    results = [u for u in upstream if isinstance(u, TaskResult)]
    failed = {u.key: u for u in results if not u.status.succeeded}
    out = {}
    for arg, spec in inputs.items():
        if isinstance(spec, DictInput):
            out[arg] = {name: s.load(store) for name, s in spec.items.items() if _usable(s, failed)}
        elif isinstance(spec, StackInput):
            kept = [np.asarray(s.load(store)) for s in spec.parts if _usable(s, failed)]
            out[arg] = np.stack(kept) if kept else None
        elif isinstance(spec, (PairsInput, SparsePairsInput)):
            tiles = set(spec.deps())
            drop = frozenset(e[2] for u in results if u.key in tiles for e in u.left_out)
            out[arg] = spec.load(store, drop=drop)
        else:
            out[arg] = spec.load(store)
    return out


def _usable(spec: InputSpec, failed: dict[str, "TaskResult"]) -> bool:
    return not (set(spec.deps()) & failed.keys()) and not (isinstance(spec, ValueInput) and spec.error)


class _Skip(Exception):
    """The task cannot run: an input it needs as a whole did not succeed (or no item of a collection did)."""

    def __init__(self, because: str, error: str):
        self.because, self.error = because, error


def _why(up: "TaskResult") -> str:
    return up.error or (f"skipped because {up.because} did not succeed" if up.because else up.status.value)


def _root(up: "TaskResult") -> str:
    """The task that failed first: a skipped task names the one it was skipped for."""
    return up.because if up.status is TaskStatus.SKIPPED and up.because else (up.display or up.stage)


def left_out_items(call: TaskCall, upstream: tuple) -> tuple[tuple[str, str, str, str], ...]:
    """The items this task is computed without, as (task key, failed task, item, why), sorted: the key of the
    upstream task it lost, the task that failed first ("views[s003]"), the item name and the error.

    An item of a collection input (``views[*]``, a pair tile's stacks) whose upstream task failed or was
    skipped, or whose dataset entry is unusable (e.g. a missing view), is left out; the items an upstream
    result was computed without are inherited. Raises _Skip when a non-collection input did not succeed, a
    pairs input lost a whole tile, or a collection has no item left.
    """
    results = [u for u in upstream if isinstance(u, TaskResult)]
    failed = {u.key: u for u in results if not u.status.succeeded}
    entries = {e for u in results if u.status.succeeded for e in u.left_out}
    for arg, spec in call.inputs.items():
        bad = set(spec.deps()) & failed.keys()
        if isinstance(spec, (DictInput, StackInput)):
            parts = list(spec.items.items()) if isinstance(spec, DictInput) else [("", p) for p in spec.parts]
            for name, part in parts:
                for k in sorted(set(part.deps()) & bad):
                    up = failed[k]
                    entries.add((k, _root(up), name or up.label, _why(up)))
                if isinstance(part, ValueInput) and part.error:
                    entries.add(("", f"{arg}[{name}]", name, part.error))
            if isinstance(spec, DictInput) and parts and not any(_usable(p, failed) for _, p in parts):
                raise _Skip(arg, f"no item of input '{arg}' succeeded")
        elif bad:
            up = failed[sorted(bad)[0]]
            raise _Skip(_root(up), _why(up))
    wired = {k for spec in call.inputs.values() for k in spec.deps()}
    for k in sorted(failed.keys() - wired):  # an upstream task no input names: nothing can be left out
        raise _Skip(_root(failed[k]), _why(failed[k]))
    return tuple(sorted(entries))


def _in_dask_worker() -> bool:
    """True inside a dask worker (whose process the engine sets up; in the caller's own process the CLI, or the
    program calling the API, decides how logging looks). A process that never imported ``distributed`` is no
    worker, and is spared its import (about a second)."""
    if "distributed" not in sys.modules:
        return False
    try:
        from distributed import get_worker
        get_worker()
        return True
    except (ImportError, ValueError):
        return False


def run_task(call: TaskCall, *upstream: TaskResult) -> TaskResult:
    """Execute one task; never raises (see :class:`TaskStatus` for the outcomes).

    One bad item does not sink a collection: a task whose collection input has items that failed upstream
    runs on the others, and records which items it left out and why (``TaskResult.left_out``, and the
    ``left_out`` of its manifest ``info``; see :func:`left_out_items`). A result computed without some items
    is run again once those items are retried (Plan.missing): cached at once if the same items fail again.
    """
    base = TaskResult(call.key, call.stage, call.label, TaskStatus.OK, display=call.display)
    try:
        left_out = left_out_items(call, upstream)
    except _Skip as skip:
        return base.with_status(TaskStatus.SKIPPED, because=skip.because, error=skip.error)
    failed = {u.key: u for u in upstream if isinstance(u, TaskResult) and not u.status.succeeded}
    store = open_store(call.cache, warn=False)  # the client warns about unusable entries
    manifest = None if call.force else store.complete(call.key)
    if manifest is not None:
        stored = tuple(tuple(e) for e in left_out_of(manifest))
        if stored == left_out:  # complete, or left out the same items as now
            return base.with_status(TaskStatus.CACHED, left_out=stored)
    fn = registry.get(call.function)
    try:
        inputs = load_inputs(store, call.inputs, upstream)
    except CorruptEntry as exc:
        return base.with_status(TaskStatus.CORRUPT, corrupt_key=exc.key, error=str(exc))
    except InputError as exc:
        return base.with_status(TaskStatus.FAILED, error=f"{type(exc).__name__}: {exc}")
    kwargs = dict(call.params)
    if "item_name" in fn.engine_args:
        kwargs["item_name"] = call.item_name
    out_dir = None
    if "out_dir" in fn.engine_args:
        out_dir = store.tmp_dir()
        kwargs["out_dir"] = out_dir
    if _in_dask_worker():   # what the function logs (e.g. a mesh repair) reaches stderr as one line, as in the CLI
        configure_logging()
    t0 = time.perf_counter()
    try:
        if audit.enabled():  # tests and plugin checks: every project function that runs must be in the key
            value = audit.audited(lambda: _call(fn, call, inputs, kwargs, failed), call.display, fn.func, fn.mirror)
        else:
            value = _call(fn, call, inputs, kwargs, failed)
    except Exception as exc:  # reported per item; the other tasks go on
        if out_dir:
            shutil.rmtree(out_dir, ignore_errors=True)
        return base.with_status(TaskStatus.FAILED, error=f"{type(exc).__name__}: {exc}",
                                traceback=traceback.format_exc(limit=8), seconds=time.perf_counter() - t0)
    seconds = time.perf_counter() - t0
    try:
        store.put(call.key, value, info={"stage": call.stage, "label": call.label, "function": call.function,
                                         "seconds": seconds, "pid": os.getpid(),
                                         "left_out": [list(e) for e in left_out]}, files_dir=out_dir)
    except TypeError as exc:
        return base.with_status(TaskStatus.FAILED, error=f"result of {call.function} cannot be stored: {exc}",
                                seconds=seconds)
    return base.with_status(TaskStatus.OK, seconds=seconds, left_out=left_out,
                            item_skipped=value.why if isinstance(value, Skipped) else "")


def _call(fn: registry.StageFunction, call: TaskCall, inputs: dict[str, Any], kwargs: dict,
          failed: dict[str, TaskResult]) -> Any:
    """Call the function; a pair tile with left-out items is computed on the kept items and stored with their
    positions (inputs.partial_tile), or not computed at all when A or B kept none. A task of a candidate pair
    stage (an input ``pairs``) likewise keeps the pairs of kept items (inputs.partial_pairs)."""
    if fn.fanout != "pair":
        return fn.func(**inputs, **kwargs)
    kept = {arg: [i for i, p in enumerate(call.inputs[arg].parts) if _usable(p, failed)] for arg in ("A", "B")}
    complete = all(len(kept[a]) == len(call.inputs[a].parts) for a in ("A", "B"))
    if "pairs" in call.inputs:
        return _call_on_pairs(fn, call, inputs, kwargs, kept if not complete else None)
    if complete:
        return fn.func(**inputs, **kwargs)
    block = fn.func(**inputs, **kwargs) if kept["A"] and kept["B"] else None
    return partial_tile(block, kept["A"], kept["B"])


def _call_on_pairs(fn: registry.StageFunction, call: TaskCall, inputs: dict[str, Any], kwargs: dict,
                   kept: dict[str, list[int]] | None) -> Any:
    """A candidate pair task: ``fn(A, B, pairs=(p, 2))`` -> (p, ...). kept: the positions of the usable items of
    A and B when some failed upstream (None: all usable); the pairs of the others are left out."""
    pairs = inputs.pop("pairs")
    if kept is None:
        return _checked_pair_values(fn, fn.func(**inputs, pairs=pairs, **kwargs), len(pairs))
    position = {}
    for arg in ("A", "B"):  # stack position -> position among the kept items (-1: left out)
        position[arg] = np.full(len(call.inputs[arg].parts), -1, dtype=np.int64)
        position[arg][kept[arg]] = np.arange(len(kept[arg]))
    a, b = position["A"][pairs[:, 0]], position["B"][pairs[:, 1]]
    rows = np.flatnonzero((a >= 0) & (b >= 0))
    if not rows.size:
        return partial_pairs(None, [])
    local = np.stack([a[rows], b[rows]], axis=1)
    return partial_pairs(_checked_pair_values(fn, fn.func(**inputs, pairs=local, **kwargs), len(local)), rows.tolist())


def _checked_pair_values(fn: registry.StageFunction, values: Any, n_pairs: int) -> np.ndarray:
    """The function's values for ``n_pairs`` pairs as an array (p, ...); ValueError naming it otherwise."""
    values = np.asarray(values)
    if values.ndim == 0 or len(values) != n_pairs:
        raise ValueError(f"{fn.name} was called with pairs= ({n_pairs}, 2) and returned shape {values.shape}; "
                         f"a pair function given pairs must return one value per pair, shape ({n_pairs}, ...)")
    return values
