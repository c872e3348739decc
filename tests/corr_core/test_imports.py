"""The import structure of the shape code (``corr_core``, the ``shapecorr`` wrappers, the bench/ scripts): no
module imports another's ``_private`` names, and no import cycle, counting imports inside functions. The checker
itself (tests/import_graph.py) is tried on small made-up packages."""
from __future__ import annotations

import textwrap

from tests.import_graph import find_cycle, graph


def test_no_module_imports_another_modules_private_names():
    assert graph(("corr_core", "shapecorr"), scanned=("bench",))[1] == []


def test_no_import_cycle_in_the_shape_code():
    cycle = find_cycle(graph(("corr_core", "shapecorr"))[0])
    assert cycle is None, " -> ".join(cycle)


def _package(tmp_path, files: dict[str, str], scanned: tuple[str, ...] = ()):
    for path, text in files.items():
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(textwrap.dedent(text))
    return graph(("pkg",), scanned=scanned, root=tmp_path)


def test_an_import_inside_a_function_closes_a_cycle(tmp_path):
    edges, _ = _package(tmp_path, {"pkg/__init__.py": "", "pkg/a.py": "from pkg.b import g\n",
                                   "pkg/b.py": "def g():\n    from pkg.a import f\n"})
    assert find_cycle(edges) == ["pkg.a", "pkg.b", "pkg.a"]


def test_a_name_from_the_own_package_init_is_a_cycle_and_a_submodule_is_not(tmp_path):
    files = {"pkg/__init__.py": "from pkg.sub import f\nh = 1\n", "pkg/sub.py": "from pkg import other\n",
             "pkg/other.py": ""}
    assert find_cycle(_package(tmp_path, files)[0]) is None
    files["pkg/sub.py"] = "from pkg import h\n"
    assert find_cycle(_package(tmp_path, files)[0]) == ["pkg", "pkg.sub", "pkg"]


def test_private_names_imported_or_read_from_another_module_are_found(tmp_path):
    _, private = _package(tmp_path, {"pkg/__init__.py": "", "pkg/_hidden.py": "def f(): pass\n",
                                     "pkg/a.py": "def _x(): pass\n_y = 1\n",
                                     "pkg/b.py": "from pkg.a import _x\nfrom pkg import a\nz = a._y\n"})
    assert private == ["pkg.b: from pkg.a import _x", "pkg.b: a._y"]


def test_a_private_module_is_private_to_its_top_level_package(tmp_path):
    files = {"pkg/__init__.py": "", "pkg/_hidden.py": "def f(): pass\n", "pkg/a.py": "from pkg._hidden import f\n",
             "tool/run.py": "from pkg._hidden import f\n"}
    assert _package(tmp_path, files, scanned=("tool",))[1] == ["tool.run: imports the private module pkg._hidden"]
