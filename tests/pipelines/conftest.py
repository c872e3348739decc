"""The one audited cold run of the default pipeline (``pipeline.yaml``, 2 workers, ``STAGES_AUDIT_CODE=1``),
shared by every test that needs it (test_default_pipeline.py, test_deterministic.py): it is the longest single
step of the suite, so it runs once per session. Tests that use it are marked ``e2e``."""
from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path
from subprocess import CompletedProcess

import pytest

from tests.helpers import ROOT, cli


@dataclass(frozen=True)
class DefaultRun:
    """A cold ``python -m stages run pipeline.yaml --summary-json s.json`` in ``folder`` (a copy of pipeline.yaml,
    the default ./cache and ./results/demo there): its process and run summary. Read it; do not change what is
    stored (a rerun that computes nothing, ``results`` and ``report`` are fine)."""
    folder: Path
    res: CompletedProcess
    summary: dict


@pytest.fixture(scope="session")
def default_cold_run(tmp_path_factory) -> DefaultRun:
    folder = tmp_path_factory.mktemp("default_run")
    shutil.copy(ROOT / "pipeline.yaml", folder / "pipeline.yaml")
    # audited: a project function that runs outside its task's code fingerprint fails the task (stages/audit.py;
    # the course pipelines: tests/pipelines/test_code_audit.py)
    res = cli(["run", "pipeline.yaml", "--summary-json", "s.json"], cwd=folder, timeout=1200,
              env={"STAGES_AUDIT_CODE": "1"})
    summary = json.loads((folder / "s.json").read_text()) if (folder / "s.json").is_file() else {}
    return DefaultRun(folder, res, summary)
