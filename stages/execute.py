"""Running the cache misses of one or more plans under dask.distributed, with progress.

Only misses are submitted; each task's dask key is deterministic (stage, item, key), so two runs sharing a
scheduler share work. Tasks whose inputs turn out corrupt are invalidated and the plan is rebuilt and run
again, with a warning.
"""
from __future__ import annotations

import os
import shutil
import sys
import time
from dataclasses import dataclass, field

from .plan import Plan, Task
from .store import Store
from .worker import run_task


@dataclass
class Outcome:
    """What happened to the tasks of a run, per stage."""
    results: dict[str, dict] = field(default_factory=dict)   # key -> status dict
    wall_seconds: float = 0.0

    def failed(self) -> list[dict]:
        return [r for r in self.results.values() if r["status"] in ("failed",)]

    def corrupt(self) -> list[dict]:
        return [r for r in self.results.values() if r["status"] == "corrupt"]


def task_spec(task: Task, store: Store) -> dict:
    return {"key": task.key, "stage": task.stage, "label": task.label, "function": task.function,
            "params": task.params, "inputs": task.inputs, "item_name": task.item_name,
            "cache": store.root, "display": task.display}


class Progress:
    """Per-stage progress: a redrawn bar on a terminal, plain lines (every 10 %) otherwise."""

    def __init__(self, totals: dict[str, int], quiet: bool = False, stream=None):
        self.totals, self.done, self.failed = totals, {s: 0 for s in totals}, {s: 0 for s in totals}
        self.quiet = quiet
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.last_pct = {s: -1 for s in totals}
        self.t0 = self.last_print = time.time()

    def update(self, stage: str, ok: bool) -> None:
        self.done[stage] += 1
        if not ok:
            self.failed[stage] += 1
        if self.quiet:
            return
        total, done = self.totals[stage], self.done[stage]
        pct = int(100 * done / max(total, 1))
        fail = f", {self.failed[stage]} failed" if self.failed[stage] else ""
        if self.tty:
            width = 24
            bar = "#" * (width * done // max(total, 1))
            self.stream.write(f"\r  {stage:<16} [{bar:<{width}}] {done}/{total}{fail}  {time.time() - self.t0:6.1f}s ")
            if done == total:
                self.stream.write("\n")
            self.stream.flush()
        elif pct // 25 > self.last_pct[stage] // 25 or done == total or time.time() - self.last_print > 10:
            self.last_pct[stage] = pct
            self.last_print = time.time()
            if total >= 8 or done == total:
                print(f"  {stage}: {done}/{total} done{fail} ({time.time() - self.t0:.1f}s)", file=self.stream, flush=True)


def make_client(workers: int = 2, scheduler: str | None = None, local_dir: str | None = None,
                memory_limit: str = "auto"):
    """A dask.distributed Client: to ``scheduler`` if given, else a LocalCluster of ``workers`` processes."""
    from distributed import Client, LocalCluster
    import dask

    if scheduler:
        return Client(scheduler, timeout="30s")
    dask.config.set({"distributed.worker.daemon": True, "distributed.admin.tick.limit": "60s",
                     "distributed.worker.memory.terminate": False})
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                           local_directory=local_dir, memory_limit=memory_limit, silence_logs=40)
    return Client(cluster)


def execute(tasks: list[Task], store: Store, client=None, quiet: bool = False, stream=None,
            key_suffix: str = "") -> Outcome:
    """Run ``tasks`` (cache misses, in dependency order); ``client=None`` runs them in this process.

    key_suffix: appended to the dask keys. A repair pass after a corrupt input must not reuse the first pass's
    keys, or the scheduler may hand back the first pass's (corrupt) results instead of running the tasks again.
    """
    outcome = Outcome()
    t0 = time.time()
    unique: dict[str, Task] = {}
    for t in tasks:
        unique.setdefault(t.key, t)
    totals: dict[str, int] = {}
    for t in unique.values():
        totals[t.stage] = totals.get(t.stage, 0) + 1
    progress = Progress(totals, quiet=quiet, stream=stream)
    if client is None:
        for t in unique.values():
            ups = [outcome.results[k] for k in t.deps if k in outcome.results]
            res = run_task(task_spec(t, store), *ups)
            res["display"] = t.display
            outcome.results[t.key] = res
            progress.update(t.stage, res["status"] in ("ok", "cached"))
    else:
        from distributed import as_completed

        futures = {}
        for t in unique.values():
            ups = [futures[k] for k in t.deps if k in futures]
            dask_key = f"{t.stage}-{t.label or 'once'}-{t.key[:16]}{key_suffix}".replace(" ", "_")
            futures[t.key] = client.submit(run_task, task_spec(t, store), *ups, key=dask_key, retries=0)
        by_future = {f.key: k for k, f in futures.items()}
        for fut in as_completed(list(futures.values())):
            key = by_future[fut.key]
            t = unique[key]
            try:
                res = fut.result()
            except Exception as exc:  # worker died (memory, segfault) or the scheduler lost the task
                res = {"key": key, "stage": t.stage, "label": t.label, "status": "failed", "seconds": 0.0,
                       "error": f"{type(exc).__name__}: {exc}"}
            res["display"] = t.display
            outcome.results[key] = res
            progress.update(t.stage, res["status"] in ("ok", "cached"))
        for f in futures.values():
            f.release()
    outcome.wall_seconds = time.time() - t0
    return outcome


def clean_tmp(store: Store, older_than_s: float = 3600) -> None:
    """Remove half-written temporary folders left by killed runs (older than ``older_than_s``)."""
    base = os.path.join(store.root, "tmp")
    if not os.path.isdir(base):
        return
    now = time.time()
    for name in os.listdir(base):
        path = os.path.join(base, name)
        try:
            if now - os.path.getmtime(path) > older_than_s:
                shutil.rmtree(path, ignore_errors=True)
        except OSError:
            pass
