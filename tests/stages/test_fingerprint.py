"""Code fingerprints: what changes a stage's code digest and what does not."""
from __future__ import annotations

import importlib
import sys
import textwrap
import uuid

import pytest

from stages.fingerprint import code_fingerprint

BASE = '''
SCALE = 2.0

def helper(x):
    """Helper docstring."""
    return x * SCALE

def other(x):
    return x + 1

def stage(x):
    """Stage docstring."""
    # a comment
    return helper(x) + 1
'''


@pytest.fixture
def load(tmp_path, monkeypatch):
    """Import ``source`` as module ``fp_mod`` (each version from its own folder, so names are equal and no
    stale bytecode is reused); returns the module."""
    from stages import fingerprint

    monkeypatch.setitem(fingerprint._DISK, "path", None)    # no on-disk digest cache from other tests

    def _load(source: str):
        folder = tmp_path / uuid.uuid4().hex[:8]
        folder.mkdir()
        (folder / "fp_mod.py").write_text(textwrap.dedent(source))
        sys.modules.pop("fp_mod", None)
        monkeypatch.syspath_prepend(str(folder))
        mod = importlib.import_module("fp_mod")
        sys.path.remove(str(folder))
        return mod

    yield _load
    sys.modules.pop("fp_mod", None)


def digest(mod):
    return code_fingerprint(mod.stage)[0]


def test_docstrings_comments_and_formatting_do_not_count(load):
    a = load(BASE)
    b = load(BASE.replace('"""Stage docstring."""', '"""Another text."""').replace("# a comment", "# other")
             .replace("return helper(x) + 1", "return   helper( x )+1"))
    assert digest(a) == digest(b)


def test_a_change_in_the_body_or_a_reached_helper_or_constant_counts(load):
    base = digest(load(BASE))
    assert digest(load(BASE.replace("helper(x) + 1", "helper(x) + 2"))) != base
    assert digest(load(BASE.replace("return x * SCALE", "return x * SCALE * 1"))) != base
    assert digest(load(BASE.replace("SCALE = 2.0", "SCALE = 3.0"))) != base
    # a function the stage does not reach does not count
    assert digest(load(BASE.replace("return x + 1", "return x + 2"))) == base


def test_parts_name_each_reached_object(load):
    mod = load(BASE)
    _, parts = code_fingerprint(mod.stage)
    names = set(parts)
    assert f"{mod.__name__}.stage" in names and f"{mod.__name__}.helper" in names
    assert f"const:{mod.__name__}.SCALE" in names
    assert f"{mod.__name__}.other" not in names


def test_only_declared_packages_are_followed(load, tmp_path):
    (tmp_path / "fp_dep_pkg").mkdir(exist_ok=True)
    (tmp_path / "fp_dep_pkg" / "__init__.py").write_text("def dep(x):\n    return x * 5\n")
    sys.modules.pop("fp_dep_pkg", None)
    sys.path.insert(0, str(tmp_path))
    mod = load("from fp_dep_pkg import dep\n\ndef stage(x):\n    return dep(x)\n")
    _, outside = code_fingerprint(mod.stage)
    _, inside = code_fingerprint(mod.stage, ("fp_dep_pkg",))
    assert "fp_dep_pkg.dep" not in outside          # third-party: pinned by versions, not followed
    assert "fp_dep_pkg.dep" in inside               # a plugin-declared package: followed
    sys.modules.pop("fp_dep_pkg", None)
    sys.path.remove(str(tmp_path))


TABLE = '''
def step_a(x):
    return x + 1

def step_b(x):
    return x * 2

STEPS = {"a": step_a, "b": step_b}

def stage(x, name="a"):
    return STEPS[name](x)
'''


def test_a_dispatch_table_constant_is_hashed_by_names_and_follows_its_functions(load):
    first = code_fingerprint(load(TABLE).stage)
    again = code_fingerprint(load(TABLE).stage)            # another import: other function addresses
    assert first == again
    assert "fp_mod.step_a" in first[1] and "fp_mod.step_b" in first[1]
    assert digest(load(TABLE.replace("return x * 2", "return x * 3"))) != first[0]   # a held function's body
