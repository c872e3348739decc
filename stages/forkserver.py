"""The local workers' fork server: one process imports what a worker needs once, and every local worker is forked
from it, instead of each worker starting a fresh interpreter and importing everything itself.

What a worker imports (dask, the engine, the plugins its pipeline names and their ``worker_warmup``: Open3D,
pyplot, ...) took about 2 s of CPU per worker, paid twice on a 2-core machine while the client was planning and
writing the generated datasets. ``run`` starts the server (``held``) before it plans, with the plugins the
pipeline file names, so those imports use the core planning leaves idle; the local cluster then forks its
workers from it (dask's ``distributed.worker.multiprocessing-method: forkserver``, Python's
``multiprocessing.forkserver``, see ``stages.worker_preload``). The default pipeline's cold run: 36.9 -> 34.5 s
(`python bench/demo.py --repeats 3 --baseline-ref 1b5f1d7`, docs/engine.md "Execution").

- Fresh code: the server is started afresh when the first holder takes it and stopped when the last lets go
  (normally: one run), so a worker never runs modules imported before an edit that the cache key already sees.
- The workers' environment (one BLAS thread, dask's hash seed, ``WORKER_IMPORTS_ENV``) is the server's: it is
  started with those variables (and ``sys.path`` as ``PYTHONPATH``, which the preload puts back), this process's
  own environment is left as it was.
- A server that cannot be started or stopped leaves the workers to dask's default (spawn): slower, never wrong.
"""
from __future__ import annotations

import json
import multiprocessing
import multiprocessing.forkserver
import os
import signal
import sys
import threading
from contextlib import contextmanager, nullcontext
from typing import Iterable, Iterator

from .blas import put_back_environ
from .worker_boot import WORKER_IMPORTS_ENV

PRELOAD = "stages.worker_preload"     # the module the server imports before it forks anything
SAVED_PYTHONPATH_ENV = "STAGES_FORKSERVER_PYTHONPATH"   # the user's PYTHONPATH as JSON (null: none), put back

_LOCK = threading.Lock()
_holders = 0        # holders of the running server (``acquire`` / ``release``)


@contextmanager
def ctrl_c_ignored_by_children() -> Iterator[None]:
    """Ignore SIGINT while child processes start, so they inherit "ignore" (a Ctrl-C to the process group then
    reaches only this process, which closes the cluster): no traceback from every worker. Only from the main
    thread (elsewhere signal handlers cannot be changed: the children set it themselves)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def acquire(plugin_names: Iterable[str], environ: dict[str, str]) -> bool:
    """Hold the fork server: start it (stopping any server started before, ours or dask's) when nothing holds
    it, preloading ``plugin_names`` (``registry`` plugin names) with ``environ`` (the workers' variables) added to
    its environment; join it when something does. Returns False when it could not be started (then nothing is
    held: the caller's workers are spawned)."""
    global _holders
    with _LOCK:
        if _holders and _server_pid() is not None:
            _holders += 1
            return True
        try:
            _kill_server()
            _start_server(list(plugin_names), environ)
        except Exception:  # noqa: BLE001 -- only a head start: spawned workers do the same imports themselves
            _kill_server()
            return False
        _holders = 1
        return True


def release() -> None:
    """Let go of the server held by ``acquire``; the last holder stops it (at once: its workers are closed by
    then, and one still importing is not waited for)."""
    global _holders
    with _LOCK:
        if _holders == 0:
            return
        _holders -= 1
        if _holders == 0:
            try:
                _kill_server()
            except Exception:  # noqa: BLE001 -- an unknown Python's server: it ends with this process
                pass


@contextmanager
def held(plugin_names: Iterable[str] | None, environ: dict[str, str]) -> Iterator[bool]:
    """``acquire`` for the body (nothing when ``plugin_names`` is None); yields whether the server is held."""
    got = plugin_names is not None and acquire(plugin_names, environ)
    try:
        yield got
    finally:
        if got:
            release()


def holding() -> bool:
    """True while some caller holds a running server (a local cluster made now may fork its workers from it)."""
    with _LOCK:
        return _holders > 0 and _server_pid() is not None


def _server() -> object:
    return multiprocessing.forkserver._forkserver   # Python's one fork server per process (what dask uses too)


def _server_pid() -> int | None:
    pid = getattr(_server(), "_forkserver_pid", None)
    return pid if isinstance(pid, int) else None


def _start_server(plugin_names: list[str], environ: dict[str, str]) -> None:
    """Start Python's fork server with ``PRELOAD`` and the given environment (this process's is put back)."""
    multiprocessing.get_context("forkserver").set_forkserver_preload([PRELOAD])
    saved = os.environ.get("PYTHONPATH")
    extra = {**environ, WORKER_IMPORTS_ENV: ",".join(plugin_names),
             # the server is a fresh interpreter: it finds the engine where this process does
             "PYTHONPATH": os.pathsep.join(p for p in sys.path if p),
             SAVED_PYTHONPATH_ENV: json.dumps(saved)}
    before = {var: os.environ.get(var) for var in extra}
    try:
        os.environ.update(extra)
        with ctrl_c_ignored_by_children():
            multiprocessing.forkserver.ensure_running()
    finally:
        put_back_environ(before)
    if _server_pid() is None:
        raise RuntimeError("the fork server did not start")


def put_back_pythonpath() -> None:
    """In the server (``stages.worker_preload``): the user's PYTHONPATH again, for what the workers start."""
    saved = os.environ.pop(SAVED_PYTHONPATH_ENV, None)
    if saved is None:
        return
    value = json.loads(saved)
    if value is None:
        os.environ.pop("PYTHONPATH", None)
    else:
        os.environ["PYTHONPATH"] = value


def _kill_server() -> None:
    """Stop Python's fork server now, if one runs, and forget it (the next start makes a fresh one). Its workers
    live on (a cluster still using them is unaffected); only new workers need a server."""
    server = _server()
    with getattr(server, "_lock", None) or nullcontext():
        pid = _server_pid()
        if pid is None:
            return
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        try:
            os.waitpid(pid, 0)
        except ChildProcessError:
            pass
        alive_fd = getattr(server, "_forkserver_alive_fd", None)
        if isinstance(alive_fd, int):
            try:
                os.close(alive_fd)
            except OSError:
                pass
        address = getattr(server, "_forkserver_address", None)
        if isinstance(address, str) and not address.startswith("\0"):
            try:
                os.unlink(address)
            except OSError:
                pass
        server._forkserver_pid = None
        server._forkserver_alive_fd = None
        server._forkserver_address = None
