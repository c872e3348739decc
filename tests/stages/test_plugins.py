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


LAZY_PLUGIN = """\
from stages.registry import Plugin
PLUGIN = Plugin(name="{name}", packages=("{name}",), modules=("{name}.funcs",), namespaces=("{space}",))
"""
LAZY_FUNCS = """\
from stages.registry import register

@register("{space}.f")
def f():
    return 1

@register("{stray}.g")
def g():
    return 2
"""


def _lazy_plugin(tmp_path, monkeypatch, name: str, space: str, stray: str) -> registry.Plugin:
    """Declare the plugin ``name`` (modules ``name.funcs``, registering ``SPACE.f`` and ``STRAY.g``) in a copy of
    the registry that is dropped after the test, so a later listing of every name does not import it."""
    for table in ("_REGISTRY", "_PLUGINS", "_UNIMPORTED"):
        monkeypatch.setattr(registry, table, dict(getattr(registry, table)))
    package = tmp_path / name
    package.mkdir()
    (package / "__init__.py").write_text(LAZY_PLUGIN.format(name=name, space=space))
    (package / "funcs.py").write_text(LAZY_FUNCS.format(space=space, stray=stray))
    monkeypatch.syspath_prepend(str(tmp_path))
    return registry.load_plugin(name)


def test_a_plugin_declaring_its_modules_is_imported_when_one_of_its_names_is_looked_up(tmp_path, monkeypatch):
    import sys

    _lazy_plugin(tmp_path, monkeypatch, "lazy_plugin_mod", "lazyns", "lazyns")
    assert "lazy_plugin_mod.funcs" not in sys.modules                  # declared, not imported
    assert registry.find("lazyns.nope") is None and "lazy_plugin_mod.funcs" in sys.modules
    assert registry.get("lazyns.g").module == "lazy_plugin_mod.funcs"
    assert "lazy_plugin_mod" in registry.imported_plugins()


def test_a_lazy_plugin_registering_outside_its_namespaces_or_half_declared_is_an_error(tmp_path, monkeypatch):
    _lazy_plugin(tmp_path, monkeypatch, "stray_plugin_mod", "strayns", "elsewhere")
    with pytest.raises(PipelineError, match="registers 'elsewhere.g' outside its namespaces strayns"):
        registry.get("strayns.f")
    with pytest.raises(PipelineError, match="declares modules without namespaces"):
        registry.add_plugin(registry.Plugin("half", modules=("x",)))


def test_a_pipeline_of_other_plugins_imports_none_of_the_application_and_nor_do_its_workers(tmp_path):
    """The engine running the synthetic test pipeline in its own process (``--workers 0``: nor dask.distributed),
    and the local workers it starts, do not import the application's modules (a second each); once the process has
    looked up an application function, the workers it starts import them at boot, before their first task, and do
    the application's ``worker_warmup`` (pyplot and Open3D)."""
    import subprocess
    import sys

    from tests.helpers import make_project, plugins_env

    path = make_project(tmp_path, n=2)
    script = f"""
import sys
from stages import api, registry
from stages.execute import make_client
probe = lambda: sorted(m for m in ("shapecorr.alignment", "shapecorr.dense", "matplotlib.pyplot", "open3d")
                       if m in sys.modules)
api.run({str(path)!r}, workers=0, cache_dir={str(tmp_path / 'cache')!r}, output_dir={str(tmp_path / 'out')!r},
        quiet=True)
print(probe(), "distributed" in sys.modules)
for step in ("other", "application"):
    if step == "application":
        registry.get("align.solve")
    client = make_client(1, local_dir={str(tmp_path / 'dask')!r})
    print(step, registry.imported_plugins(), list(client.run(probe).values()))
    cluster = client.cluster
    client.close()
    cluster.close()
"""
    env = {**__import__("os").environ, **plugins_env()}
    res = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines() == ["[] False", "other [] [[]]",
                                       "application ['shapecorr'] [['matplotlib.pyplot', 'open3d', "
                                       "'shapecorr.alignment', 'shapecorr.dense']]"]   # + its worker_warmup


def test_a_lazy_module_that_cannot_be_imported_is_the_same_error_at_every_look_up(tmp_path, monkeypatch):
    _lazy_plugin(tmp_path, monkeypatch, "broken_plugin_mod", "brokenns", "brokenns")
    (tmp_path / "broken_plugin_mod" / "funcs.py").write_text("import no_such_dependency_xyz\n")
    for _ in range(2):      # not "unknown function" the second time
        with pytest.raises(PipelineError, match="cannot import module broken_plugin_mod.funcs of plugin "
                                                "'broken_plugin_mod': No module named 'no_such_dependency_xyz'"):
            registry.get("brokenns.f")


WARM_EXTRA = """\
CALLS = []

def mark():
    CALLS.append("mark")

def boom():
    raise RuntimeError("a warm-up that fails")
"""


def test_a_plugins_worker_warmup_imports_and_calls_its_entries_and_skips_those_that_fail(tmp_path, monkeypatch):
    import dataclasses
    import sys

    plugin = _lazy_plugin(tmp_path, monkeypatch, "warm_plugin_mod", "warmns", "warmns")
    (tmp_path / "warm_plugin_mod" / "extra.py").write_text(WARM_EXTRA)
    registry.add_plugin(dataclasses.replace(plugin, worker_warmup=(
        "no_such_module_xyz", "warm_plugin_mod.extra:boom", "warm_plugin_mod.extra:no_such_function",
        "warm_plugin_mod.extra:mark", "warm_plugin_mod.funcs")))
    registry.warm_up(["warm_plugin_mod", "no_such_plugin"])
    assert sys.modules["warm_plugin_mod.extra"].CALLS == ["mark"]     # after the failing entries
    assert "warm_plugin_mod.funcs" in sys.modules
    registry.warm_up([])
    assert sys.modules["warm_plugin_mod.extra"].CALLS == ["mark"]     # only the plugins named
