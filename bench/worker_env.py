"""The same numpy-heavy work in this process and in a dask worker, with dask's default worker environment and
with the engine's (``stages.execute.WORKER_ENVIRON``): the cost of MALLOC_TRIM_THRESHOLD_; then with the engine's
environment and dask's profiler on, as dask has it, and off, as the engine's local workers have it
(``stages.execute.worker_profile_config``): the cost of the profiler.

The work: ``mobius.score_maps`` (600 random triplet maps, 300 x 300 samples, as ``corr.match_mobius`` scores 5
sparse landmarks) and a dense map between two generated humanoid poses (``dense_map`` with its defaults on
``make_humanoid_dataset(n_poses=1, seed=10)``: ZoomOut, refinement, ARAP). Each is run 3 times per place (best time);
the workers are a 1-worker ``LocalCluster`` per environment, started once and warmed up by one run. Printed: the
seconds per place and their ratio to this process (one BLAS thread here too).

Run:  python bench/worker_env.py
"""
from __future__ import annotations

import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()


def mobius_scores() -> float:
    """Seconds of one ``score_maps`` call on fixed random data."""
    import numpy as np
    from corr_core.correspondence.mobius import score_maps

    rng = np.random.default_rng(0)
    maps = [rng.standard_normal((600, 4)) + 1j * rng.standard_normal((600, 4)) for _ in range(2)]
    Z = [rng.standard_normal(300) + 1j * rng.standard_normal(300) for _ in range(2)]
    lam = [rng.random(300) + 0.5 for _ in range(2)]
    t0 = time.perf_counter()
    score_maps(*maps, *Z, K=0.5, metric="surface", lam_s=lam[0], lam_t=lam[1], K_scale=0.7)
    return time.perf_counter() - t0


def dense_pair() -> float:
    """Seconds of one ``dense_map`` between two generated poses (the bases included)."""
    from corr_core.correspondence.dense import dense_map
    from corr_core.generate.humanoid import make_humanoid_dataset

    V, F, poses, *_ = make_humanoid_dataset(n_poses=1, seed=10)
    t0 = time.perf_counter()
    dense_map(V, F, poses[0], F, k=60)
    return time.perf_counter() - t0


def best_of(job, repeats: int = 3) -> float:
    return min(job() for _ in range(repeats))


def in_worker(environ: dict, jobs, profile: bool = True) -> list[float]:
    """Best seconds of each job in a 1-worker LocalCluster whose worker process gets ``environ``, with dask's
    profiler on or off."""
    saved = {k: os.environ.pop(k) for k in ("MALLOC_TRIM_THRESHOLD_",) if k in os.environ}
    try:        # the nanny also sets its variables in this process, whose environment a later worker inherits
        return _run_jobs(environ, jobs, profile)
    finally:
        os.environ.pop("MALLOC_TRIM_THRESHOLD_", None)
        os.environ.update(saved)


def _run_jobs(environ: dict, jobs, profile: bool) -> list[float]:
    import dask
    from distributed import Client, LocalCluster

    with dask.config.set({"distributed.nanny.pre-spawn-environ": environ,
                          "distributed.worker.profile.enabled": profile}):
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                Client(cluster) as client:
            out = []
            for job in jobs:
                client.submit(job, pure=False).result()                  # warm up: imports, caches
                out.append(client.submit(best_of, job, pure=False).result())
            return out


def main() -> int:
    import dask
    import distributed  # noqa: F401  (its import loads dask's distributed.* defaults)
    from stages.execute import WORKER_ENVIRON

    jobs = (mobius_scores, dense_pair)
    for job in jobs:
        job()                                                            # warm up this process
    here = [best_of(job) for job in jobs]
    dask_default = dict(dask.config.get("distributed.nanny.pre-spawn-environ"))
    places = {"this process": here, f"worker, dask's environment {dask_default}": in_worker(dask_default, jobs),
              f"worker, the engine's {WORKER_ENVIRON}, dask's profiler on": in_worker(dict(WORKER_ENVIRON), jobs),
              f"worker, the engine's {WORKER_ENVIRON}, profiler off (the engine's local workers)":
                  in_worker(dict(WORKER_ENVIRON), jobs, profile=False)}
    for place, seconds in places.items():
        print(place)
        for job, s, h in zip(jobs, seconds, here):
            print(f"  {job.__name__:<14} {s:7.3f} s   ratio to this process {s / h:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
