"""What every command needs: a logger, and a dask client started only when something must run."""
from __future__ import annotations

import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from typing import Any, Callable, Iterator

from .execute import make_client


def stderr_log(quiet: bool) -> Callable[..., None]:
    """A ``print``-like function writing to stderr, or one that does nothing when ``quiet``."""
    return (lambda *a, **k: None) if quiet else (lambda *a, **k: print(*a, **k, file=sys.stderr, flush=True))


@contextmanager
def client_session(workers: int, scheduler: str | None, cache_dir: str,
                   log: Callable[..., None] | None = None) -> Iterator[Callable[[], Any]]:
    """Yield a function returning a dask client, started on its first call (``None`` for ``workers=0`` without a
    scheduler: run in this process); the client and its local cluster are closed at the end.

    ``get.start_early()`` starts it in a thread now (a local cluster takes about a second, and its workers then
    import the stage library): the caller goes on preparing (writing generated datasets) meanwhile, and the
    first ``get()`` waits for it. Its log lines (the dashboard address) are printed then, in order; an error
    starting it is raised by ``get()``."""
    holder: dict[str, Any] = {}
    lock = threading.Lock()

    def start(log_to) -> None:
        with lock:
            if "client" in holder or "error" in holder:
                return
            try:
                if workers == 0 and not scheduler:
                    holder["client"] = None
                else:
                    local = os.path.join(cache_dir, "tmp", "dask-worker-space")
                    os.makedirs(local, exist_ok=True)
                    holder["client"] = make_client(workers, scheduler, local_dir=local, log=log_to)
            except BaseException as exc:  # noqa: BLE001 -- raised again by get(), in the caller's thread
                holder["error"] = exc

    def get():
        starter = holder.get("starter")
        if starter is not None:
            starter.join()
            for line in holder.pop("early_log", []):
                if log is not None:
                    log(line)
        start(log)
        if "error" in holder:
            raise holder["error"]
        return holder["client"]

    def start_early() -> None:
        if "starter" in holder or "client" in holder or (workers == 0 and not scheduler):
            return
        lines: list[str] = []
        holder["early_log"] = lines
        holder["starter"] = threading.Thread(target=start, args=(lines.append if log else None,),
                                             name="stages-cluster-start", daemon=True)
        holder["starter"].start()

    get.start_early = start_early
    try:
        yield get
    finally:
        starter = holder.get("starter")
        if starter is not None:
            starter.join()
        client = holder.get("client")
        if client is not None:
            close_client(client, own_cluster=not scheduler, log=log)


# For the client and its local cluster together. From a Ctrl-C to the exit of the process takes 0.7-4.3 s on this
# machine, loaded or not (`python bench/ctrl_c.py --tries 8 --burn 2`: 1.9-2.6 s; see its docstring): 15 s leaves
# room for a slower machine and still ends a stuck close long before dask's own 60 s.
CLOSE_TIMEOUT_S = 15.0


def close_client(client, own_cluster: bool, timeout_s: float = CLOSE_TIMEOUT_S,
                 log: Callable[..., None] | None = None) -> None:
    """Close ``client`` and, when ``own_cluster``, its local cluster, within ``timeout_s`` seconds in all (the
    cluster gets at least 1 s of its own when the client took nearly all of it).

    A close that fails or does not finish in time (dask's event loop stuck after a Ctrl-C, a worker that does not
    answer) neither hangs the command nor replaces its outcome (its exit code, a Ctrl-C): every result is stored
    already. The local cluster's worker processes are then killed and ``log`` gets one warning line.
    """
    cluster = getattr(client, "cluster", None) if own_cluster else None
    deadline = time.monotonic() + timeout_s
    try:
        client.close(timeout=timeout_s)
        if cluster is not None:
            cluster.close(timeout=max(deadline - time.monotonic(), 1.0))
    except Exception as exc:  # noqa: BLE001 -- dask's TimeoutError, a connection error, ...
        killed = _kill_worker_processes(cluster) if cluster is not None else 0
        if log is not None:
            log(f"warning: dask did not shut down cleanly within {timeout_s:g} s ({type(exc).__name__}: "
                f"{str(exc).splitlines()[0] if str(exc) else 'no detail'}); "
                f"{killed} local worker process(es) killed. Every finished result is stored.")


def _kill_worker_processes(cluster) -> int:
    """SIGKILL the worker processes of a dask LocalCluster (its nannies' children): the number killed."""
    killed = 0
    for nanny in list(getattr(cluster, "workers", {}).values()):
        pid = getattr(getattr(getattr(nanny, "process", None), "process", None), "pid", None)
        if not isinstance(pid, int) or pid == os.getpid():
            continue
        try:
            os.kill(pid, signal.SIGKILL)
            killed += 1
        except (ProcessLookupError, PermissionError):
            pass
    return killed


@contextmanager
def given_client(getter: Callable[[], Any]) -> Iterator[Callable[[], Any]]:
    """A client the caller owns (tests, benchmarks): used as is, never closed here."""
    yield getter
