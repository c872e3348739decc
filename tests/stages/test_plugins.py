"""Plugins: the application registers through the stages.plugins entry point; the engine knows nothing of it."""
from __future__ import annotations

import ast
import importlib.metadata
import json
from pathlib import Path

import pytest

from stages import registry
from stages.errors import PipelineError

from tests.helpers import ROOT, cli

ENGINE = ROOT / "stages"


def test_production_lists_the_application_and_no_test_functions(tmp_path):
    res = cli(["functions", "--json"], cwd=tmp_path, env={"STAGES_PLUGINS": ""})
    assert res.returncode == 0, res.stderr
    names = {r["name"] for r in json.loads(res.stdout)}
    assert {"align.solve", "corr.evaluate", "generate.chairs"} <= names
    assert not any(n.startswith("synthetic.") for n in names)
    res = cli(["functions", "--json"], cwd=tmp_path)            # the development hook adds the test plugin
    assert "synthetic.features" in {r["name"] for r in json.loads(res.stdout)}


def test_the_application_is_an_installed_entry_point():
    eps = {ep.name: ep.value for ep in importlib.metadata.entry_points(group=registry.ENTRY_POINT_GROUP)}
    assert eps.get("shapecorr") == "shapecorr:PLUGIN"
    plugin = registry.load_plugin(eps["shapecorr"])
    assert set(plugin.packages) == {"corr_core", "shapecorr"}
    assert {"corr_core", "shapecorr"} <= set(registry.fingerprint_packages())
    assert registry.get("align.solve").group in plugin.groups
    assert registry.group_titles()["alignment"] == plugin.groups["alignment"]


def test_plugins_of_a_pipeline_are_those_that_registered_its_functions():
    names = [p.name for p in registry.plugins(["synthetic.features"])]
    assert names == ["synthetic"]
    assert "shapecorr" in [p.name for p in registry.plugins(["align.solve"])]


def test_a_bad_plugin_name_is_a_clear_error():
    with pytest.raises(PipelineError, match="(?s)cannot import plugin 'no_such_plugin_mod'.*STAGES_PLUGINS"):
        registry.load_plugin("no_such_plugin_mod")
    with pytest.raises(PipelineError, match="has no attribute 'NOPE'"):
        registry.load_plugin("tests.stages.synthetic_plugin:NOPE")


def test_a_module_without_a_plugin_object_is_a_plugin_of_its_own_code(tmp_path, monkeypatch):
    (tmp_path / "bare_plugin_mod.py").write_text(
        "from stages.registry import register\n\n@register('bare.f')\ndef f():\n    return 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    plugin = registry.load_plugin("bare_plugin_mod")
    assert plugin.packages == ("bare_plugin_mod",) and registry.get("bare.f").module == "bare_plugin_mod"


def _imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            out.add(node.value)                                # e.g. importlib.import_module("...")
    return out


def test_the_engine_names_neither_the_algorithms_nor_the_application():
    for path in ENGINE.rglob("*.py"):
        for name in _imported_modules(path):
            assert not name.split(".")[0] in ("corr_core", "shapecorr"), f"{path.relative_to(ROOT)}: {name}"
