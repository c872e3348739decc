"""The engine's import structure (issue 24): no module imports another's ``_private`` names, and no import cycle,
counting imports inside functions (an import moved into a function to dodge a cycle is still a cycle)."""
from __future__ import annotations

import ast
import pathlib

import stages

ROOT = pathlib.Path(stages.__file__).parent


def _modules() -> dict[str, ast.Module]:
    """{dotted name: parsed source} of every module of the ``stages`` package."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = ("stages",) + path.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = (ast.parse(path.read_text()), parts[-1] == "__init__")
    return out


def _imports(name: str, tree: ast.Module, is_package: bool) -> list[tuple[str, list[str]]]:
    """(imported module, names taken from it) of every import statement in ``tree``, wherever it stands."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = name.split(".")[:len(name.split(".")) - node.level + is_package] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            out.append((module, [a.name for a in node.names]))
    return out


def _graph() -> tuple[dict[str, set[str]], list[str]]:
    """({module: the stages modules it imports}, private names imported from another stages module)."""
    modules = _modules()
    graph: dict[str, set[str]] = {m: set() for m in modules}
    private = []
    for name, (tree, is_package) in modules.items():
        for module, names in _imports(name, tree, is_package):
            targets = [module] + [f"{module}.{n}" for n in names]
            parts = module.split(".")
            targets += [".".join(parts[:i]) for i in range(1, len(parts))]   # importing a.b runs a first
            graph[name] |= {t for t in targets if t in modules and t != name and not name.startswith(t + ".")}
            if module.startswith("stages"):
                private += [f"{name}: from {module} import {n}" for n in names if n.startswith("_")
                            and not n.startswith("__")]
    return graph, private


def test_no_module_imports_another_modules_private_names():
    assert _graph()[1] == []


def test_no_import_cycle_in_the_engine():
    graph = _graph()[0]
    done: set[str] = set()

    def cycle_from(m: str, path: list[str]) -> list[str] | None:
        if m in path:
            return path[path.index(m):] + [m]
        if m in done:
            return None
        for t in sorted(graph[m]):
            found = cycle_from(t, path + [m])
            if found:
                return found
        done.add(m)
        return None

    for m in sorted(graph):
        assert cycle_from(m, []) is None, " -> ".join(cycle_from(m, []))
