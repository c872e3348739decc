"""Preloaded by every worker process of the local cluster (``distributed.worker.preload``), before its first task.

- Ctrl-C: the worker ignores SIGINT, so a Ctrl-C to the process group reaches only the client process, which
  shuts the cluster down cleanly (no traceback from every worker). Set here as well as inherited at spawn
  (``execute._ctrl_c_ignored_by_children``), because the cluster may be started from a thread, where the
  client cannot change signal handlers.
- The stage functions' modules are imported now, while the client is still planning and writing generated
  datasets, instead of by the worker's first task (0.7 s here): the plugins (``registry.load_library``), and
  the modules of those the client has imported for its pipeline (``WORKER_IMPORTS_ENV``, set by
  ``execute.make_client``), not the others, and then those plugins' ``worker_warmup`` (e.g. the libraries their
  functions import on first use). A plugin that fails to import is reported by the task that needs it.
"""
from __future__ import annotations

import os
import signal

WORKER_IMPORTS_ENV = "STAGES_WORKER_IMPORTS"   # comma-separated plugin names (registry.imported_plugins)


def dask_setup(worker) -> None:
    """distributed's preload hook: runs in the worker process's main thread when the worker starts."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        from . import registry
        registry.load_library()
        plugin_names = [n for n in os.environ.get(WORKER_IMPORTS_ENV, "").split(",") if n]
        registry.import_plugins(plugin_names)
        registry.warm_up(plugin_names)
    except Exception:  # noqa: BLE001 -- the task that needs the plugin reports the error, with its traceback
        pass
