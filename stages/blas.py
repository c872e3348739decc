"""One BLAS/OpenMP thread for the work the engine runs in its own process, as in its local workers.

A result must not depend on where a task ran. A multi-threaded BLAS splits a product's sums across threads, so
the last bits of e.g. a matrix product depend on the thread count: run in-process (``--workers 0``) with the
machine's default threads, 35 of the default pipeline's 295 alignment numbers differed from a 2-worker run's,
whose workers have one thread each (``stages.execute.WORKER_ENVIRON``). Tasks and generators run in this process
therefore get one thread too, through :func:`one_blas_thread`.
"""
from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Iterator

import threadpoolctl

# read by OpenBLAS, MKL and OpenMP when they are loaded: the libraries a task loads for the first time
BLAS_THREAD_ENVIRON = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the body with one BLAS/OpenMP thread in this process, then put back the threads and variables found.

    The libraries already loaded are limited through threadpoolctl; those loaded inside the body read the
    environment variables, set for its duration (they keep one thread afterwards: a library reads them once)."""
    before = {var: os.environ.get(var) for var in BLAS_THREAD_ENVIRON}
    os.environ.update(BLAS_THREAD_ENVIRON)
    try:
        with threadpoolctl.threadpool_limits(1):
            yield
    finally:
        for var, value in before.items():
            if value is None:
                os.environ.pop(var, None)
            else:
                os.environ[var] = value
