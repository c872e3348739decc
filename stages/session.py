"""What every command needs: a logger, and a dask client started only when something must run."""
from __future__ import annotations

import os
import sys
import threading
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
            cluster = getattr(client, "cluster", None)
            client.close()
            if cluster is not None and not scheduler:
                cluster.close()


@contextmanager
def given_client(getter: Callable[[], Any]) -> Iterator[Callable[[], Any]]:
    """A client the caller owns (tests, benchmarks): used as is, never closed here."""
    yield getter
