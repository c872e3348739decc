"""Shared fixtures: a real dask LocalCluster for the whole session, and helpers for engine tests."""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest
import threadpoolctl

from stages.blas import BLAS_THREAD_ENVIRON
from tests.helpers import BLAS_ENVIRON_BEFORE, COURSE_DATA, SYNTHETIC_PLUGIN, machine_blas_environ

# One BLAS/OpenMP thread in each test process: the 2 pytest-xdist workers already fill the 2 cores, and a second
# thread per worker only competed with the other worker (the dense-map unit tests took 81 s instead of 47 s, the
# whole command 349 s instead of 325 s: `python -m pytest -q --durations=0` with and without, 2026-12-07). The
# variables reach the libraries loaded later (scipy's OpenBLAS, OpenMP) and the processes the tests start;
# threadpool_limits sets the libraries already loaded (a pytest plugin imports numpy before this file). The
# engine's own worker processes get the same from stages.execute.WORKER_ENVIRON (see ``dask_client``).
# the values before this file, kept for the processes this one starts (pytest-xdist's workers load it again):
# ``machine_blas_environ`` puts them back
os.environ.setdefault(BLAS_ENVIRON_BEFORE, json.dumps({var: os.environ.get(var) for var in BLAS_THREAD_ENVIRON}))
os.environ.update(BLAS_THREAD_ENVIRON)
threadpoolctl.threadpool_limits(1)

# The synthetic.* stage functions are a test-only plugin, loaded through the STAGES_PLUGINS development hook
# (in this process and in the dask workers and CLI subprocesses it starts, which inherit the environment).
os.environ["STAGES_PLUGINS"] = ",".join(filter(None, [os.environ.get("STAGES_PLUGINS", ""), SYNTHETIC_PLUGIN]))


@pytest.fixture(scope="session")
def dask_client(tmp_path_factory):
    """A real LocalCluster (2 worker processes, 1 thread each) shared by the engine tests."""
    from stages.execute import make_client

    with pytest.MonkeyPatch.context() as mp:   # the workers' one thread must come from the engine, not this file
        machine_blas_environ(mp)
        client = make_client(workers=2, local_dir=str(tmp_path_factory.mktemp("dask")))
    yield client
    cluster = client.cluster
    client.close()
    cluster.close()


# Seconds each long module's tests took (--durations=0, summed per module), apart for the README's test command
# (LONG_MODULES: the tests not marked e2e; a fresh clone, 2026-12-06, "984 passed, 2 skipped in 236.66s", the report
# browser's 6 from 2026-12-03, when a browser was installed) and for the e2e run (LONG_E2E_MODULES: pytest -m e2e,
# quiet machine, 2026-12-03). The 2 pytest-xdist workers (-n 2 in pyproject.toml's addopts) take the longest xdist
# group first (a group's weight is the sum over its modules), so no long group starts last while the other worker
# idles. Groups not listed keep the collection order after these.
LONG_MODULES = {
    "tests/corr_core/correspondence/dense/test_dense_map.py": 58,
    "tests/pipelines/test_correspondence_pipeline.py": 55, "tests/stages/test_store_s3.py": 46,
    "tests/pipelines/test_dense_pipeline.py": 45, "tests/stages/test_help_examples.py": 34,
    "tests/stages/test_cli.py": 21, "tests/stages/test_user_errors.py": 16,
    "tests/pipelines/test_alignment_pipeline.py": 14, "tests/stages/test_candidates.py": 12,
    "tests/corr_core/alignment/test_continuous.py": 8, "tests/stages/test_cli_in_process.py": 7,
    "tests/corr_core/correspondence/test_orientation.py": 7, "tests/pipelines/test_candidate_graph.py": 6,
    "tests/stages/test_cache_integrity.py": 6, "tests/stages/test_report_browser.py": 6,
    "tests/stages/test_run.py": 5, "tests/test_packaging.py": 5, "tests/corr_core/alignment/test_sync.py": 5,
    "tests/stages/test_pure_planning.py": 5,
}
LONG_E2E_MODULES = {
    "tests/pipelines/test_code_audit.py": 77, "tests/stages/test_cli.py": 71,
    "tests/pipelines/test_deterministic.py": 60, "tests/pipelines/test_default_pipeline.py": 53,
    "tests/pipelines/test_scale.py": 21, "tests/stages/test_failed_items.py": 16, "tests/stages/test_store_s3.py": 16,
    "tests/stages/test_report_browser.py": 10, "tests/stages/test_user_errors.py": 8,
}
# Session fixtures shared across modules: the modules using one run on the same xdist worker (one run each).
SHARED_SESSION_FIXTURES = ("default_cold_run",)


@pytest.hookimpl(tryfirst=True)   # before xdist's worker reads the xdist_group marks, and before -m deselects
def pytest_collection_modifyitems(config, items):
    # One xdist group per module (--dist loadgroup): a module's tests run in order on one worker, so its module
    # fixtures (a generated dataset, a pipeline run, a cache its tests build on) are computed once.
    group_of = {}
    for item in items:
        module = item.nodeid.split("::")[0]
        shared = [f for f in SHARED_SESSION_FIXTURES if f in getattr(item, "fixturenames", ())]
        group_of[item.nodeid] = shared[0] if shared else module
        item.add_marker(pytest.mark.xdist_group(group_of[item.nodeid]))
    # weight of (group, e2e or not): the sum of its modules' seconds in that run
    modules = {}
    for item in items:
        key = (group_of[item.nodeid], item.get_closest_marker("e2e") is not None)
        modules.setdefault(key, set()).add(item.nodeid.split("::")[0])
    weight = {key: sum((LONG_E2E_MODULES if key[1] else LONG_MODULES).get(m, 0) for m in mods)
              for key, mods in modules.items()}
    items.sort(key=lambda item: -weight[(group_of[item.nodeid], item.get_closest_marker("e2e") is not None)])

    if COURSE_DATA.is_dir():
        return
    skip = pytest.mark.skip(reason=f"course data not found at {COURSE_DATA}")
    for item in items:
        if "course" in item.keywords:
            item.add_marker(skip)
