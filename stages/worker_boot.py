"""Preloaded by every worker process of the local cluster (``distributed.worker.preload``), before its first task.

- Ctrl-C: the worker ignores SIGINT, so a Ctrl-C to the process group reaches only the client process, which
  shuts the cluster down cleanly (no traceback from every worker). Set here as well as inherited at spawn
  (``execute._ctrl_c_ignored_by_children``), because the cluster may be started from a thread, where the
  client cannot change signal handlers.
- The stage functions' modules (``registry.load_library``) are imported now, while the client is still planning
  and writing generated datasets, instead of by the worker's first task (0.7 s here). A plugin that fails to
  import is reported by the task that needs it, as before.
"""
from __future__ import annotations

import signal


def dask_setup(worker) -> None:
    """distributed's preload hook: runs in the worker process's main thread when the worker starts."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        from . import registry
        registry.load_library()
    except Exception:  # noqa: BLE001 -- the task that needs the plugin reports the error, with its traceback
        pass
