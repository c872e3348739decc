"""Every project function a stage actually runs is in its cache key: the course pipelines under the code audit.

The audit (``stages.audit``, ``STAGES_AUDIT_CODE=1``) runs each task under ``sys.setprofile`` and fails it when a
project function executed that its code fingerprint does not cover. The default pipeline is audited by
``test_default_pipeline.py`` (its cold run, shared in conftest.py, has the audit on); here the course pipelines,
on a few items each, so that every stage of ``pipelines/scape.yaml`` and ``pipelines/chairs.yaml`` runs at least once.
"""
from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import json
import shutil
import textwrap

import pytest

from stages import registry
from stages.fingerprint import code_fingerprint

from tests.helpers import COURSE_DATA, ROOT, cli

AUDIT = {"STAGES_AUDIT_CODE": "1", "STAGES_PLUGINS": ""}


def _audited_run(tmp_path, pipeline: str, sets: list[str]) -> dict:
    """Run ``pipeline`` (copied into tmp_path) with the audit on; the run summary."""
    shutil.copy(ROOT / pipeline, tmp_path / "p.yaml")
    args = ["run", "p.yaml", "--cache", "cache", "--out", "out", "--summary-json", "s.json", "--quiet"]
    res = cli(args + [a for s in sets for a in ("--set", s)], cwd=tmp_path, env=AUDIT, timeout=1500)
    assert "code audit" not in res.stdout + res.stderr, (res.stdout + res.stderr)[-4000:]
    assert res.returncode == 0, res.stderr[-3000:]
    summary = json.loads((tmp_path / "s.json").read_text())
    ran = {name for name, s in summary["stages"].items() if s["executed"]}
    return summary, ran


@pytest.mark.course
@pytest.mark.slow
@pytest.mark.e2e
def test_scape_pipeline_stages_run_only_fingerprinted_code(tmp_path):
    src = COURSE_DATA / "scape"
    data = tmp_path / "scape"
    for sub in ("meshes/template", "meshes/test", "flattened_meshes/template", "flattened_meshes/test"):
        (data / sub).mkdir(parents=True)
    for kind in ("meshes", "flattened_meshes"):
        (data / kind / "template" / "mesh000.obj").symlink_to(src / kind / "template" / "mesh000.obj")
        for name in ("mesh002",):
            (data / kind / "test" / f"{name}.obj").symlink_to(src / kind / "test" / f"{name}.obj")
    for name in ("landmark_vids.txt", "sparse_landmark_vids.txt", "uniform_sample_vids.txt"):
        (data / name).symlink_to(src / name)
    summary, ran = _audited_run(tmp_path, "pipelines/scape.yaml", [f"data.root={data}"])
    assert ran == set(summary["stages"]), set(summary["stages"]) - ran     # every stage ran, audited


@pytest.mark.course
@pytest.mark.e2e
def test_chairs_pipeline_stages_run_only_fingerprinted_code(tmp_path):
    views, meshes = tmp_path / "views", tmp_path / "meshes"
    views.mkdir()
    meshes.mkdir()
    for name in ("001", "002", "003", "004", "005"):
        for v in range(16):
            (views / f"{name}_{v}.png").symlink_to(COURSE_DATA / "chairs_rendering" / f"{name}_{v}.png")
        (meshes / f"{name}.obj").symlink_to(COURSE_DATA / "chairs" / f"{name}.obj")
    summary, ran = _audited_run(tmp_path, "pipelines/chairs.yaml",
                                [f"data.root={views}", f"data.compare_root={meshes}"])
    assert ran == set(summary["stages"]), set(summary["stages"]) - ran


def _part_object(part: str):
    """The function or class a fingerprint part names (``pkg.mod.Qual.name``), or None for the other kinds."""
    if ":" in part:
        return None
    parts = part.split(".")
    for i in range(len(parts) - 1, 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    return None


def _local_project_imports(obj, package: str, project: tuple[str, ...]):
    """(module, name) of every ``from M import name`` inside the body of a function or class, M in project."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(obj)))
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = importlib.util.resolve_name("." * node.level + (node.module or ""), package) \
                if node.level else node.module
            if module.split(".")[0] in project:
                for alias in node.names:
                    yield module, alias.name


def test_every_function_local_import_of_a_reached_function_is_in_the_stage_key():
    """A static cross-check written independently of ``stages.fingerprint``: for every registered function, each
    project function or class imported inside the body of a function it reaches is reached too (on the landed
    main of 2026-12-01 ``refine_deform`` was imported inside ``refine_map`` and missing from corr.dense_refine)."""
    registry.load_library()
    packages = registry.fingerprint_packages()
    checked = 0
    for name in registry.names():
        func = registry.get(name).func
        _, parts = code_fingerprint(func, packages)
        for part in parts:
            obj = _part_object(part)
            if obj is None or not (inspect.isfunction(obj) or inspect.isclass(obj)):
                continue
            package = obj.__module__.rpartition(".")[0]
            for module, imported in _local_project_imports(obj, package, packages):
                target = getattr(importlib.import_module(module), imported)
                if inspect.isfunction(target) or inspect.isclass(target):
                    assert f"{target.__module__}.{target.__qualname__}" in parts, (name, part, imported)
                    checked += 1
    assert checked >= 5
    _, parts = code_fingerprint(registry.get("corr.dense_refine").func, packages)
    assert "corr_core.correspondence.dense.deform.refine_deform" in parts
