"""Imported once by the local workers' fork server (``stages.forkserver``) before it forks any worker: what every
worker would import for itself (dask's worker, the engine, the plugins in ``WORKER_IMPORTS_ENV`` and their
``worker_warmup``), so each forked worker starts with it. Never raises: a plugin that fails to import is
reported by the task that needs it, as with spawned workers (``stages.worker_boot``)."""
import signal

signal.signal(signal.SIGINT, signal.SIG_IGN)   # the workers inherit it: a Ctrl-C reaches only the client

try:
    from stages import forkserver, worker, worker_boot   # noqa: F401 -- worker: what every task calls
    import distributed.nanny                             # noqa: F401 -- a worker process's own code

    forkserver.put_back_pythonpath()
    worker_boot.import_stage_library()
except Exception:  # noqa: BLE001 -- a head start only; the workers import what they need themselves
    pass
