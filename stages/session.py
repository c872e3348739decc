"""What every command needs: a logger, and a dask client started only when something must run."""
from __future__ import annotations

import os
import sys
from contextlib import contextmanager
from typing import Any, Callable, Iterator

from .execute import make_client


def stderr_log(quiet: bool) -> Callable[..., None]:
    """A ``print``-like function writing to stderr, or one that does nothing when ``quiet``."""
    return (lambda *a, **k: None) if quiet else (lambda *a, **k: print(*a, **k, file=sys.stderr, flush=True))


@contextmanager
def client_session(workers: int, scheduler: str | None, cache_dir: str,
                   log: Callable[..., None] | None = None) -> Iterator[Callable[[], Any]]:
    """Yield a function returning a dask client, started lazily on first call (``None`` for ``workers=0``
    without a scheduler: run in this process); the client and its local cluster are closed at the end."""
    holder: dict[str, Any] = {}

    def get():
        if "client" not in holder:
            if workers == 0 and not scheduler:
                holder["client"] = None
            else:
                local = os.path.join(cache_dir, "tmp", "dask-worker-space")
                os.makedirs(local, exist_ok=True)
                holder["client"] = make_client(workers, scheduler, local_dir=local, log=log)
        return holder["client"]

    try:
        yield get
    finally:
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
