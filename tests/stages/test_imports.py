"""The engine's import structure: no module imports another's ``_private`` names, and no import cycle,
counting imports inside functions (an import moved into a function to dodge a cycle is still a cycle)."""
from __future__ import annotations

from tests.import_graph import find_cycle, graph


def test_no_module_imports_another_modules_private_names():
    assert graph(("stages",))[1] == []


def test_no_import_cycle_in_the_engine():
    cycle = find_cycle(graph(("stages",))[0])
    assert cycle is None, " -> ".join(cycle)
