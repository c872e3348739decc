"""The local cluster's worker processes: one BLAS thread each, and no MALLOC_TRIM_THRESHOLD_ (dask's default
makes numpy-heavy tasks 2-3x slower in a worker: stages.execute.WORKER_ENVIRON)."""
from __future__ import annotations

import os


def _worker_environment() -> dict:
    return {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}


def test_local_workers_run_with_one_blas_thread_and_glibcs_own_malloc_thresholds(dask_client):
    seen = dask_client.run(_worker_environment)
    assert len(seen) == 2
    for env in seen.values():
        assert env == {"MALLOC_TRIM_THRESHOLD_": None, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
