"""What runs on a dask worker: load a task's inputs from the store, call the function, store the result.

A task never raises to dask: it returns a small status dict, so one failing item is reported with its
name while the others finish, and dependents of a failed task are skipped rather than crashed.
"""
from __future__ import annotations

import os
import shutil
import time
import traceback
from typing import Any

import numpy as np

from . import registry
from .errors import CorruptEntry
from .store import Store


def load_input(store: Store, spec: dict) -> Any:
    """Materialize one input spec (see plan.py) into the value the function receives."""
    kind = spec["kind"]
    if kind == "value":
        return spec["value"]
    if kind == "entry":
        return store.get(spec["key"])  # the store keeps a per-process cache of decoded entries
    if kind == "dict":
        return {name: load_input(store, s) for name, s in spec["items"].items()}
    if kind == "stack":
        return np.stack([np.asarray(load_input(store, s)) for s in spec["parts"]])
    if kind == "pairs":
        return assemble_pairs(store, spec)
    raise ValueError(f"unknown input kind {kind}")


def assemble_pairs(store: Store, spec: dict) -> dict:
    """The full (N, N, ...) matrix of a pair stage from its upper-triangle tiles.

    Returns {"names": [N names], "matrix": (N, N, ...) array}; lower tiles come from the function's mirror.
    """
    fn = registry.get(spec["mirror"])
    names, blocks = spec["names"], spec["blocks"]
    n = len(names)
    matrix = None
    for bi, bj, key in spec["tiles"]:
        block = np.asarray(store.get(key))
        (s0, e0), (s1, e1) = blocks[bi], blocks[bj]
        if matrix is None:
            matrix = np.full((n, n) + block.shape[2:], np.nan, dtype=block.dtype)
        matrix[s0:e0, s1:e1] = block
        if bi != bj:
            matrix[s1:e1, s0:e0] = fn.mirror(block) if fn.mirror is not None else np.swapaxes(block, 0, 1)
    if matrix is None:
        matrix = np.zeros((0, 0))
    return {"names": list(names), "matrix": matrix}


def run_task(spec: dict, *upstream: dict) -> dict:
    """Execute one task described by ``spec`` (from execute.task_spec); returns a status dict.

    status: "ok" | "cached" (someone else stored it meanwhile) | "failed" | "skipped" (an upstream task
    failed) | "corrupt" (an input entry failed its checksum: the client recomputes it).
    """
    base = {"key": spec["key"], "stage": spec["stage"], "label": spec["label"], "seconds": 0.0}
    for up in upstream:
        if isinstance(up, dict) and up.get("status") not in ("ok", "cached"):
            return {**base, "status": "skipped", "because": up.get("display", up.get("stage"))}
    store = Store(spec["cache"])
    if store.has(spec["key"]):
        return {**base, "status": "cached"}
    fn = registry.get(spec["function"])
    try:
        inputs = {arg: load_input(store, s) for arg, s in spec["inputs"].items()}
    except CorruptEntry as exc:
        return {**base, "status": "corrupt", "corrupt_key": exc.key, "error": str(exc)}
    kwargs = dict(spec["params"])
    if "item_name" in fn.engine_args:
        kwargs["item_name"] = spec["item_name"]
    out_dir = None
    if "out_dir" in fn.engine_args:
        out_dir = store.tmp_dir()
        kwargs["out_dir"] = out_dir
    t0 = time.perf_counter()
    try:
        value = fn.func(**inputs, **kwargs)
    except Exception as exc:  # reported per item; the other tasks go on
        if out_dir:
            shutil.rmtree(out_dir, ignore_errors=True)
        return {**base, "status": "failed", "error": f"{type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc(limit=8), "seconds": time.perf_counter() - t0}
    seconds = time.perf_counter() - t0
    try:
        store.put(spec["key"], value, info={"stage": spec["stage"], "label": spec["label"],
                                            "function": spec["function"], "seconds": seconds,
                                            "pid": os.getpid()}, files_dir=out_dir)
    except TypeError as exc:
        return {**base, "status": "failed", "error": f"result of {spec['function']} cannot be stored: {exc}",
                "seconds": seconds}
    return {**base, "status": "ok", "seconds": seconds}
