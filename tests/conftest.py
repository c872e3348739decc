"""Shared fixtures: a real dask LocalCluster for the whole session, and helpers for engine tests."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from tests.helpers import COURSE_DATA, SYNTHETIC_PLUGIN

# The synthetic.* stage functions are a test-only plugin, loaded through the STAGES_PLUGINS development hook
# (in this process and in the dask workers and CLI subprocesses it starts, which inherit the environment).
os.environ["STAGES_PLUGINS"] = ",".join(filter(None, [os.environ.get("STAGES_PLUGINS", ""), SYNTHETIC_PLUGIN]))


@pytest.fixture(scope="session")
def dask_client(tmp_path_factory):
    """A real LocalCluster (2 worker processes, 1 thread each) shared by the engine tests."""
    from stages.execute import make_client

    client = make_client(workers=2, local_dir=str(tmp_path_factory.mktemp("dask")))
    yield client
    cluster = client.cluster
    client.close()
    cluster.close()


# Seconds each long module took (--durations, one run, machine shared): the 2 pytest-xdist workers (-n 2 in
# pyproject.toml's addopts) take the longest first, so no long module starts last while the other worker idles.
# Modules not listed keep the collection order after these.
LONG_MODULES = {
    "tests/stages/test_cli.py": 347, "tests/pipelines/test_dense_pipeline.py": 321,
    "tests/pipelines/test_correspondence_pipeline.py": 229, "tests/stages/test_store_s3.py": 216,
    "tests/stages/test_help_examples.py": 113, "tests/pipelines/test_alignment_pipeline.py": 106,
    "tests/corr_core/correspondence/dense/test_dense_map.py": 100, "tests/stages/test_candidates.py": 72,
    "tests/corr_core/correspondence/test_orientation.py": 56, "tests/stages/test_user_errors.py": 52,
    "tests/stages/test_report_browser.py": 47, "tests/stages/test_cli_in_process.py": 36,
    "tests/corr_core/alignment/test_sync.py": 32, "tests/stages/test_log_lines.py": 24,
    "tests/stages/test_cache_integrity.py": 24, "tests/stages/test_pure_planning.py": 22,
}
# Session fixtures shared across modules: the modules using one run on the same xdist worker (one run each).
SHARED_SESSION_FIXTURES = ("default_cold_run",)


@pytest.hookimpl(tryfirst=True)   # before xdist's worker reads the xdist_group marks
def pytest_collection_modifyitems(config, items):
    # One xdist group per module (--dist loadgroup): a module's tests run in order on one worker, so its module
    # fixtures (a generated dataset, a pipeline run, a cache its tests build on) are computed once.
    for item in items:
        module = item.nodeid.split("::")[0]
        shared = [f for f in SHARED_SESSION_FIXTURES if f in getattr(item, "fixturenames", ())]
        item.add_marker(pytest.mark.xdist_group(shared[0] if shared else module))
    weight = {}
    for item in items:
        module = item.nodeid.split("::")[0]
        weight.setdefault(module, LONG_MODULES.get(module, 0))
    items.sort(key=lambda item: -weight[item.nodeid.split("::")[0]])   # stable: order within a module kept

    if COURSE_DATA.is_dir():
        return
    skip = pytest.mark.skip(reason=f"course data not found at {COURSE_DATA}")
    for item in items:
        if "course" in item.keywords:
            item.add_marker(skip)
