"""Set-up shared by the benchmark scripts (standard library only: import it before numpy).

``one_blas_thread()``: one BLAS/OpenMP thread, so CPU seconds (``time.process_time``) count work, not idle
threads spinning on a shared machine. ``ROOT``: the project folder; ``SCAPE``: the course SCAPE data beside it.
"""
from __future__ import annotations

import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCAPE = os.path.join(os.path.dirname(ROOT), "shared", "data", "hw3", "scape")


def one_blas_thread() -> None:
    """Ask BLAS/OpenMP for one thread (takes effect for libraries loaded after this call)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
