"""The import graph of the project's packages, read from their source (``ast``, nothing is imported).

Every import statement counts, wherever it stands (an import moved into a function to dodge a cycle is still a
cycle). Used by the import tests of the engine (tests/stages/test_imports.py) and of the shape code
(tests/corr_core/test_imports.py).
"""
from __future__ import annotations

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def modules(*packages: str, root: pathlib.Path = ROOT) -> dict[str, tuple[ast.Module, bool]]:
    """{dotted name: (parsed source, is a package ``__init__``)} of every module of ``packages`` (folders under
    ``root``, this checkout by default; a folder without ``__init__.py``, such as bench/, counts as a namespace
    package)."""
    out = {}
    for package in packages:
        folder = root / package
        for path in sorted(folder.rglob("*.py")):
            parts = (package,) + path.relative_to(folder).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = (ast.parse(path.read_text()), parts[-1] == "__init__")
    return out


def imports(name: str, tree: ast.Module, is_package: bool) -> list[tuple[str, list[tuple[str, str]]]]:
    """(imported module, [(name taken from it, the local name bound)]) of every import statement in ``tree``,
    wherever it stands; ``import a.b [as x]`` gives ("a.b", [("", "x" or "a")])."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, [("", a.asname or a.name.split(".")[0])]) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = name.split(".")[:len(name.split(".")) - node.level + is_package] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            out.append((module, [(a.name, a.asname or a.name) for a in node.names]))
    return out


def graph(packages: tuple[str, ...], scanned: tuple[str, ...] = (),
          root: pathlib.Path = ROOT) -> tuple[dict[str, set[str]], list[str]]:
    """({module: the modules of ``packages`` it imports}, private names one module takes from another).

    Importing ``a.b.c`` runs ``a`` and ``a.b`` first, so it is an edge to each of them, except to the importing
    module's own packages, which are already running: ``from a.b import c`` (a submodule) inside ``a.b.d`` is
    no edge to ``a.b``, but ``from a.b import f`` (a name ``a.b/__init__.py`` defines) is. ``scanned`` packages
    (scripts such as bench/) are checked for private names but are not nodes of the graph.

    Private: a ``_name`` imported from another module, a ``_name`` read as an attribute of an imported module
    (``init._ranked``), and a module whose own name starts with ``_`` imported from outside its top-level package.
    """
    mods = modules(*packages, *scanned, root=root)
    nodes = {m for m in mods if m.split(".")[0] in packages}
    edges: dict[str, set[str]] = {m: set() for m in nodes}
    private = []
    for name, (tree, is_package) in mods.items():
        own_packages = {m for m in mods if name.startswith(m + ".")}
        module_aliases = set()
        for module, names in imports(name, tree, is_package):
            if module.split(".")[0] not in packages + scanned:
                continue
            taken = [f"{module}.{n}" if n else module for n, _ in names]
            module_aliases |= {alias for (_, alias), t in zip(names, taken) if t in mods}
            parts = module.split(".")
            targets = {t for t in taken if t in mods} | {".".join(parts[:i]) for i in range(1, len(parts) + 1)}
            waits = module in own_packages and any(t not in mods for t in taken)
            targets -= own_packages - ({module} if waits else set())
            if name in nodes:
                edges[name] |= {t for t in targets if t in nodes and t != name}
            private += [f"{name}: from {module} import {n}" for n, _ in names if _is_private(n)]
            if any(_is_private(p) for p in parts[1:]) and parts[0] != name.split(".")[0]:
                private.append(f"{name}: imports the private module {module}")
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and _is_private(node.attr) and isinstance(node.value, ast.Name)
                    and node.value.id in module_aliases):
                private.append(f"{name}: {node.value.id}.{node.attr}")
    return edges, private


def find_cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``edges`` as [m0, m1, ..., m0], or None."""
    done: set[str] = set()

    def cycle_from(m: str, path: list[str]) -> list[str] | None:
        if m in path:
            return path[path.index(m):] + [m]
        if m in done:
            return None
        for t in sorted(edges[m]):
            found = cycle_from(t, path + [m])
            if found:
                return found
        done.add(m)
        return None

    for m in sorted(edges):
        found = cycle_from(m, [])
        if found:
            return found
    return None
