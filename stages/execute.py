"""Running the cache misses of one or more plans under dask.distributed, with progress.

Only misses are submitted; each task's dask key is deterministic (stage, item, key), so two runs sharing a
scheduler share work. Tasks whose inputs turn out corrupt are invalidated and the plan is rebuilt and run
again, with a warning. :func:`execute_rounds` runs a plan in rounds: when a stage waits for the result of a
candidates stage (a pair stage on a candidate graph) and this round stored it, the pipeline is planned again
and the new misses run (like Snakemake's checkpoints).
"""
from __future__ import annotations

import collections
import heapq
import logging
import os
import re
import shutil
import signal
import statistics
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

from . import registry
from .blas import BLAS_THREAD_ENVIRON, one_blas_thread
from .errors import UserError, warn_once
from .plan import Plan, Task, build_plan
from .status import run_lines
from .store import Store
from .worker import TaskCall, TaskResult, TaskStatus, run_task
from .worker_boot import WORKER_IMPORTS_ENV


@dataclass
class Outcome:
    """What happened to the tasks of a run, per stage."""
    results: dict[str, TaskResult] = field(default_factory=dict)   # key -> result
    wall_seconds: float = 0.0

    def with_status(self, status: TaskStatus) -> list[TaskResult]:
        return [r for r in self.results.values() if r.status is status]

    def failed(self) -> list[TaskResult]:
        return self.with_status(TaskStatus.FAILED)

    def corrupt(self) -> list[TaskResult]:
        return self.with_status(TaskStatus.CORRUPT)


def task_call(task: Task, store: Store, force: bool = False) -> TaskCall:
    """What a worker needs to run ``task`` against ``store`` (``force``: replace the stored result, if any)."""
    return TaskCall(task.key, task.stage, task.label, task.function, task.params, task.inputs, task.item_name,
                    store.location, task.display, force)


class Progress:
    """Per-stage progress: a redrawn bar on a terminal, plain lines (every 10 %) otherwise."""

    def __init__(self, totals: dict[str, int], quiet: bool = False, stream=None):
        self.totals, self.done, self.failed = totals, {s: 0 for s in totals}, {s: 0 for s in totals}
        self.quiet = quiet
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.last_pct = {s: -1 for s in totals}
        self.t0 = self.last_print = time.time()
        self.first_done: dict[str, float] = {}   # stage -> time its first task finished (for the estimate)

    def eta(self, stage: str, now: float | None = None) -> str:
        """``", ~12s left"`` for a stage with at least 2 tasks done and some left (rate measured from its first
        finished task, so the scheduler's start-up does not count); ``""`` when there is no estimate."""
        now = time.time() if now is None else now
        total, done = self.totals[stage], self.done[stage]
        start = self.first_done.get(stage)
        if start is None or done < 2 or done >= total or now <= start:
            return ""
        left = (now - start) / (done - 1) * (total - done)
        return f", ~{left:.0f}s left" if left < 120 else f", ~{left / 60:.1f} min left"

    def update(self, stage: str, ok: bool) -> None:
        self.done[stage] += 1
        self.first_done.setdefault(stage, time.time())
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
            elapsed = time.time() - self.t0
            self.stream.write(f"\r  {stage:<16} [{bar:<{width}}] {done}/{total}{fail}  {elapsed:6.1f}s{self.eta(stage):<20}")
            if done == total:
                self.stream.write("\n")
            self.stream.flush()
        elif pct // 25 > self.last_pct[stage] // 25 or done == total or time.time() - self.last_print > 10:
            self.last_pct[stage] = pct
            self.last_print = time.time()
            if total >= 8 or done == total:
                print(f"  {stage}: {done}/{total} done{fail} ({time.time() - self.t0:.1f}s{self.eta(stage)})",
                      file=self.stream, flush=True)


SCHEDULER_TIMEOUT_S = 10   # default; STAGES_SCHEDULER_TIMEOUT (seconds) sets another (``scheduler_timeout``)
SCHEDULER_TIMEOUT_ENV = "STAGES_SCHEDULER_TIMEOUT"
DASHBOARD_ADDRESS = "127.0.0.1:0"  # this machine only, a free port (see docs/scale.md to expose it)


# The environment of the local worker processes: one BLAS/OpenMP thread each (a task is one thread), and *not*
# dask's default MALLOC_TRIM_THRESHOLD_=65536: with it glibc stops adapting its mmap threshold, every array above
# 128 KB is mapped and unmapped afresh, and numpy-heavy tasks ran 1.4x (a dense map) to 5x (Möbius scoring) slower
# in a worker than in a plain process (`python bench/worker_env.py`: see docs/engine.md "Execution"). Memory
# freed by a task is then kept by the worker process for the next task instead of being returned to the system.
WORKER_ENVIRON = {var: int(value) for var, value in BLAS_THREAD_ENVIRON.items()}   # as in-process tasks: blas.py
# dask's statistical profiler (``distributed.worker.profile``) wakes every 10 ms in each worker to walk the stack of
# its task thread: with numpy-heavy tasks of deep Python stacks that cost 1.1-1.2x in task time (`python
# bench/worker_env.py`, see docs/engine.md "Execution"). Off in the local workers unless the variable below is set
# (the dashboard's Profile page is then empty); a ``--scheduler`` cluster keeps its own setting.
WORKER_PROFILE_ENV = "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED"
WORKER_PRELOAD = "stages.worker_boot"   # run by each local worker at start: ignore Ctrl-C, import the stage library


def make_client(workers: int = 2, scheduler: str | None = None, local_dir: str | None = None,
                memory_limit: str = "auto", log=None):
    """A dask.distributed Client: to ``scheduler`` if given, else a LocalCluster of ``workers`` processes.

    The local cluster's dashboard listens on 127.0.0.1 only; ``log`` (a print-like function) receives its URL.
    Its worker processes ignore Ctrl-C: the client process alone handles it and shuts them down cleanly. Each
    runs ``WORKER_PRELOAD`` when it starts (``stages.worker_boot``), importing the plugins this process has
    imported so far (those of the pipeline it planned). May be called from a thread.
    dask's own log is kept to CRITICAL: a worker that dies is reported by ``execute`` as its task's failure, not
    by the surviving workers' connection-reset tracebacks.

    Raises:
        UserError: the scheduler does not answer within ``scheduler_timeout()`` seconds, or its address is
            malformed.
    """
    from distributed import Client, LocalCluster
    import dask

    if scheduler:
        return _connect(Client, scheduler)
    dask.config.set({"distributed.worker.daemon": True, "distributed.admin.tick.limit": "60s",
                     "distributed.worker.memory.terminate": False,
                     "distributed.nanny.pre-spawn-environ": dict(WORKER_ENVIRON),
                     "distributed.worker.preload": [WORKER_PRELOAD], **worker_profile_config()})
    with _ctrl_c_ignored_by_children():
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=DASHBOARD_ADDRESS, local_directory=local_dir,
                               memory_limit=memory_limit, silence_logs=logging.CRITICAL,
                               # the plugins of the pipeline being run (the nanny's env: the one setting that
                               # the client's own environment, set by an earlier cluster, does not override)
                               env={WORKER_IMPORTS_ENV: ",".join(registry.imported_plugins())})
    if log is not None and cluster.dashboard_link:
        log(f"dask dashboard: {cluster.dashboard_link}")
    return Client(cluster)


def worker_profile_config() -> dict:
    """The dask setting of the local workers' profiler: off, unless ``WORKER_PROFILE_ENV`` is set (then dask
    reads it, whatever it says)."""
    return {} if WORKER_PROFILE_ENV in os.environ else {"distributed.worker.profile.enabled": False}


def _connect(Client, address: str):
    """A Client connected to the scheduler at ``address``, or a UserError saying what to do."""
    fix = ("start a scheduler (`dask scheduler` prints its address, e.g. tcp://10.0.0.5:8786) and its workers, "
           "check the host, port and firewall, or leave out --scheduler to run on local worker processes")
    if "://" not in address and ":" not in address:
        raise UserError(f"--scheduler '{address}' is not an address like tcp://HOST:PORT", fix=fix)
    seconds = scheduler_timeout()
    try:
        return Client(address, timeout=f"{seconds:g}s")
    except (OSError, ValueError, TypeError, TimeoutError) as exc:
        raise UserError(f"cannot connect to the dask scheduler at {address} within {seconds:g} s "
                        f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else 'no answer'})",
                        fix=fix) from None


def scheduler_timeout() -> float:
    """Seconds to wait for a ``--scheduler`` to answer (dask retries a refused connection until then):
    ``STAGES_SCHEDULER_TIMEOUT`` when set, else ``SCHEDULER_TIMEOUT_S``.

    Raises:
        UserError: the variable is not a positive number of seconds.
    """
    text = os.environ.get(SCHEDULER_TIMEOUT_ENV, "").strip()
    if not text:
        return float(SCHEDULER_TIMEOUT_S)
    try:
        seconds = float(text)
    except ValueError:
        seconds = float("nan")
    if not 0 < seconds < float("inf"):
        raise UserError(f"{SCHEDULER_TIMEOUT_ENV}={text!r} is not a positive number of seconds",
                        fix=f"set it to e.g. {SCHEDULER_TIMEOUT_S} (seconds to wait for --scheduler), or unset it")
    return seconds


@contextmanager
def _ctrl_c_ignored_by_children():
    """Ignore SIGINT while worker processes start, so they inherit "ignore" (a Ctrl-C to the process group
    then reaches only this process, which closes the cluster): no traceback from every worker."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def execute(tasks: list[Task], store: Store, client=None, quiet: bool = False, stream=None,
            key_suffix: str = "", prior: dict[str, TaskResult] | None = None,
            forced: set[str] | frozenset[str] = frozenset()) -> Outcome:
    """Run ``tasks`` (cache misses, in dependency order); ``client=None`` runs them in this process.

    key_suffix: appended to the dask keys. A repair pass after a corrupt input must not reuse the first pass's
    keys, or the scheduler may hand back the first pass's (corrupt) results instead of running the tasks again.
    prior: results of upstream tasks run earlier in this run (an earlier round): passed to the tasks that depend
    on them, so items that failed there are left out here too.
    forced: keys of tasks that compute and replace their stored result even when it is there (``--force``).
    """
    prior = prior or {}
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
        with one_blas_thread():   # the threads of a local worker: the same bits as there
            for t in unique.values():
                ups = [outcome.results[k] if k in outcome.results else prior[k] for k in t.deps
                       if k in outcome.results or k in prior]
                res = run_task(task_call(t, store, t.key in forced), *ups)
                outcome.results[t.key] = res
                progress.update(t.stage, res.status.succeeded)
    else:
        _run_on_cluster(unique, store, client, outcome, progress, prior, forced, key_suffix)
    outcome.wall_seconds = time.time() - t0
    return outcome


def _run_on_cluster(tasks: dict[str, Task], store: Store, client, outcome: Outcome, progress: Progress,
                    prior: dict[str, TaskResult], forced: set[str] | frozenset[str], key_suffix: str) -> None:
    """Run ``tasks`` (in dependency order) on the cluster of ``client``, recording each result in ``outcome``.

    The engine hands a task to the scheduler only when every task it needs has finished and a worker thread is
    free (``_free_threads``), the next one by ``dispatch_order``. Tasks submitted all at once with their upstream
    futures are placed by the scheduler where their (tiny) upstream results are: at the end of a run, the last
    summaries then queued behind one another on one worker while the other idled.
    While tasks are short (the median of the last ``_RECENT`` under ``SHORT_TASK_S``) one more task per thread is
    handed over ahead, so a worker does not wait for the round trip to this process between two tasks."""
    from distributed import as_completed

    waiting_for = {k: {d for d in t.deps if d in tasks} for k, t in tasks.items()}
    dependents: dict[str, list[str]] = {k: [] for k in tasks}
    for k, needs in waiting_for.items():
        for d in needs:
            dependents[d].append(k)
    rank = dispatch_order(tasks, dependents)
    ready = [rank[k] for k, needs in waiting_for.items() if not needs]
    heapq.heapify(ready)
    in_flight: dict[str, str] = {}                       # dask key -> task key
    threads = _free_threads(client)
    running = as_completed()
    recent: collections.deque[float] = collections.deque(maxlen=_RECENT)   # seconds of the last tasks done

    def submit_ready() -> None:
        ahead = 2 if len(recent) == _RECENT and statistics.median(recent) < SHORT_TASK_S else 1
        while ready and len(in_flight) < ahead * threads():
            t = tasks[heapq.heappop(ready)[-1]]
            ups = [outcome.results[k] if k in outcome.results else prior[k] for k in t.deps
                   if k in outcome.results or k in prior]
            dask_key = f"{t.stage}-{t.label or 'once'}-{t.key[:16]}{key_suffix}".replace(" ", "_")
            running.add(client.submit(run_task, task_call(t, store, t.key in forced), *ups, key=dask_key,
                                      retries=0))
            in_flight[dask_key] = t.key

    submit_ready()
    for fut in running:
        key = in_flight.pop(fut.key)
        t = tasks[key]
        try:
            res = fut.result()
        except Exception as exc:  # worker died (memory, segfault) or the scheduler lost the task
            res = TaskResult(key, t.stage, t.label, TaskStatus.FAILED, display=t.display,
                             error=f"{type(exc).__name__}: {exc}")
        fut.release()
        recent.append(res.seconds)
        outcome.results[key] = res
        progress.update(t.stage, res.status.succeeded)
        for d in dependents[key]:
            waiting_for[d].discard(key)
            if not waiting_for[d]:
                heapq.heappush(ready, rank[d])
        submit_ready()


# Tasks shorter than this (median of the last _RECENT) are handed to the workers one ahead per thread: the round
# trip between two tasks (a few ms) then overlaps the work. `python bench/engine.py --items 300 --item-ms 5
# --pair-us 20` (300 tasks of 5 ms; noisy): all handed over at once 1.62x-2.12x the plain loop in 4 runs (median
# 1.85x), one task per free thread 1.97x in 1, with this look-ahead 1.72x-2.27x in 5 (median 1.87x).
SHORT_TASK_S = 0.2
_RECENT = 16


def dispatch_order(tasks: dict[str, Task], dependents: dict[str, list[str]]) -> dict[str, tuple]:
    """Per task key, a sort key (smaller runs first among the tasks ready at the same time): the task with the
    longest chain of tasks still to come after it first, so every chain of per-item stages progresses and the run
    does not end with one chain computed alone; ties in plan order. The last element is the key.

    A task nothing of this run waits for (a summary, a figure) therefore comes after every other ready task.
    Replaying the default pipeline's cold run (`python bench/dispatch_replay.py pipeline.yaml --cache DIR`: its
    152 tasks with their stored seconds, 70 ms each to load and store, 2 workers) this order ends at 41.6 s, plan
    order at 41.1 s, such tasks first at 41.8 s, and an order that knew every task's time (most seconds still to
    come first) at 40.8 s, the lower bound: the order matters little there."""
    depth: dict[str, int] = {}
    for key in reversed(list(tasks)):          # dependency order: a task's dependents come after it
        depth[key] = 1 + max((depth[d] for d in dependents[key]), default=0)
    return {key: (-depth[key], i, key) for i, key in enumerate(tasks)}


def _free_threads(client, refresh_s: float = 1.0):
    """A function returning the number of worker threads of ``client``'s cluster (at least 1; asked again at most
    every ``refresh_s`` seconds, as workers of an external cluster come and go)."""
    state = {"at": -float("inf"), "threads": 1}

    def threads() -> int:
        now = time.monotonic()
        if now - state["at"] > refresh_s:
            try:
                state["threads"] = max(1, sum(client.nthreads().values()))
            except Exception:  # scheduler briefly unreachable: keep the last count
                pass
            state["at"] = now
        return state["threads"]
    return threads


def execute_rounds(plans: list[Plan], get_client, quiet: bool = False, key_suffix: str = "",
                   log=None, first_missing: list[tuple[Plan, list[Task]]] | None = None
                   ) -> tuple[list[Plan], Outcome, set[str]]:
    """Run the misses of ``plans`` (sharing one store), in rounds: after a round, a plan with a stage waiting for
    a candidates stage whose result is now stored is planned again, and the new misses run; until no plan waits
    for a stored result. A candidates result found damaged while planning is invalidated (with a warning) and
    recomputed. Tasks of forced stages (``Plan.forced``) run once per run even when cached. ``get_client()`` is
    called only when something must run; ``log`` (print-like) gets, per round, one line per stage with tasks to
    run and the first reason why (:func:`stages.status.run_lines`). Returns the final plans, the outcome of every
    task run, and the keys that were missing.

    ``first_missing``: per plan, ``(the plan that listed them, its missing())`` when the caller has just listed them
    (nothing run since): the first round uses them instead of asking the store about every task again (on an
    object store, requests), for a plan that is still the one that listed them (not one planned again since)."""
    outcome, missing_all = Outcome(), set()
    given = first_missing or []
    for round_no in range(sum(len(pl.stages) for pl in plans) + 2):  # each round plans at least one more stage
        plans = [_without_damaged(pl, log) for pl in plans]
        owner: dict[str, tuple[Task, Plan]] = {}
        for i, pl in enumerate(plans):
            known = given[i][1] if round_no == 0 and given and given[i][0] is pl else None
            for t in (pl.missing() if known is None else known):
                if t.key not in outcome.results:
                    owner.setdefault(t.key, (t, pl))
        missing = [t for t, _ in owner.values()]
        if missing:
            missing_all |= {t.key for t in missing}
            if log is not None:
                log(f"running {len(missing)} task(s):" if round_no == 0 else
                    f"running {len(missing)} more task(s) now that the candidate pairs are known:")
                for line in run_lines(list(owner.values())):
                    log("  " + line)
            forced = {k for k, (t, pl) in owner.items() if pl.is_forced(t)}
            done = execute(missing, plans[0].store, get_client(), quiet=quiet,
                           key_suffix=key_suffix + (f"-round{round_no}" if round_no else ""), prior=outcome.results,
                           forced=forced)
            outcome.results.update(done.results)
            stored = {k for k, r in done.results.items() if r.status is TaskStatus.OK}
            for pl in plans:
                pl.recomputed |= stored & forced
            if done.corrupt():
                break  # the caller invalidates the corrupt inputs and runs again
        ready = [any(pl.store.has(k) for k in pl.waiting().values()) for pl in plans]
        if not any(ready):
            break
        plans = [pl.again() if r else pl for pl, r in zip(plans, ready)]
    return plans, outcome, missing_all


def _without_damaged(plan: Plan, log) -> Plan:
    """``plan``, planned again after invalidating the candidates results it found damaged (if any)."""
    if not plan.damaged_candidates:
        return plan
    for key, error in plan.damaged_candidates.items():
        warn_once(f"{error}; recomputing it")  # once, through the engine's reporter (not also a UserWarning)
        plan.store.invalidate(key)
    return plan.again()


_TMP_NAME = re.compile(r"^(trash-)?[0-9a-f]{32}$|^dask-worker-space$")


def clean_tmp(store: Store, older_than_s: float = 3600) -> None:
    """Remove half-written temporary folders left by killed runs (older than ``older_than_s``).

    Only in a folder carrying the engine's cache marker, and only names the engine gives its temporary
    folders: nothing else is ever removed."""
    base = os.path.join(store.root, "tmp")
    if not os.path.isdir(base) or not store.is_marked():
        return
    now = time.time()
    for name in os.listdir(base):
        if not _TMP_NAME.match(name):
            continue
        path = os.path.join(base, name)
        try:
            if now - os.path.getmtime(path) > older_than_s:
                shutil.rmtree(path, ignore_errors=True)
        except OSError:
            pass
