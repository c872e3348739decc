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


def pytest_collection_modifyitems(config, items):
    if COURSE_DATA.is_dir():
        return
    skip = pytest.mark.skip(reason=f"course data not found at {COURSE_DATA}")
    for item in items:
        if "course" in item.keywords:
            item.add_marker(skip)
