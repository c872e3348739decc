"""Code fingerprints: a hash of a function's AST and of the project functions it uses.

Comments, docstrings and formatting do not change a fingerprint; a change to the function or to any
project function, class or module constant it reaches (transitively) does. Third-party code is not
followed: it is pinned by the package versions recorded in each run's provenance.
"""
from __future__ import annotations

import ast
import hashlib
import inspect
import textwrap
import types
from typing import Any

PROJECT_PACKAGES = ("corr_core", "stages")


def _is_project(obj: Any, extra: frozenset = frozenset()) -> bool:
    mod = getattr(obj, "__module__", None) if not isinstance(obj, types.ModuleType) else obj.__name__
    return bool(mod) and (mod.split(".")[0] in PROJECT_PACKAGES or mod in extra)


def _strip_docstrings(tree: ast.AST) -> ast.AST:
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Module)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant) \
                    and isinstance(body[0].value.value, str):
                node.body = body[1:] or [ast.Pass()]
    return tree


def _ast_digest(obj: Any) -> tuple[str, ast.AST | None]:
    try:
        src = textwrap.dedent(inspect.getsource(obj))
        tree = _strip_docstrings(ast.parse(src))
        # decorators are wiring, not computation (the registered name is part of the key anyway)
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                node.decorator_list = []
                break
        return hashlib.blake2b(ast.dump(tree, include_attributes=False).encode(), digest_size=16).hexdigest(), tree
    except (OSError, TypeError, SyntaxError):
        return hashlib.blake2b(repr(getattr(obj, "__code__", obj)).encode(), digest_size=16).hexdigest(), None


def _referenced_names(tree: ast.AST) -> set[tuple[str, ...]]:
    """Dotted name chains loaded in ``tree``: ``np.linalg.norm`` -> ('np','linalg','norm')."""
    chains: set[tuple[str, ...]] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            parts, cur = [], node
            while isinstance(cur, ast.Attribute):
                parts.append(cur.attr)
                cur = cur.value
            if isinstance(cur, ast.Name):
                chains.add(tuple([cur.id] + parts[::-1]))
        elif isinstance(node, ast.Name):
            chains.add((node.id,))
    return chains


def _resolve(chain: tuple[str, ...], namespace: dict, extra: frozenset = frozenset()) -> list[tuple[str, Any]]:
    """Project objects reached by a dotted name chain, with their qualified names."""
    if chain[0] not in namespace:
        return []
    obj, found = namespace[chain[0]], []
    for attr in chain[1:] + (None,):
        if isinstance(obj, types.ModuleType):
            if attr is None or not _is_project(obj, extra):
                break
            if not hasattr(obj, attr):
                break
            obj = getattr(obj, attr)
            continue
        if _is_project(obj, extra) and (inspect.isfunction(obj) or inspect.isclass(obj)):
            found.append((f"{obj.__module__}.{obj.__qualname__}", obj))
        elif isinstance(obj, (int, float, str, bytes, bool, tuple, frozenset, list, dict)) and len(chain) == 1:
            found.append((f"const:{chain[0]}", obj))
        break
    return found


def code_fingerprint(func: Any) -> tuple[str, dict[str, str]]:
    """Fingerprint ``func`` and every project function/class/constant it reaches.

    "Project" means the packages ``corr_core`` and ``stages`` plus the module that defines ``func``
    (so helpers next to a plugin's stage function are tracked too).

    Returns:
        digest: one hex string over everything reached.
        parts: {qualified name: hex digest} of each reached project object (for "why will this rerun").
    """
    func = inspect.unwrap(func)
    extra = frozenset({func.__module__})
    parts: dict[str, str] = {}
    stack: list[tuple[str, Any]] = [(f"{func.__module__}.{func.__qualname__}", func)]
    while stack:
        qual, obj = stack.pop()
        if qual in parts:
            continue
        if qual.startswith("const:"):
            parts[qual] = hashlib.blake2b(repr(obj).encode(), digest_size=8).hexdigest()
            continue
        digest, tree = _ast_digest(obj)
        parts[qual] = digest
        if tree is None:
            continue
        namespace = dict(getattr(inspect.getmodule(obj), "__dict__", {}))
        if inspect.isfunction(obj) and obj.__closure__:
            namespace.update(zip(obj.__code__.co_freevars, (c.cell_contents for c in obj.__closure__)))
        for chain in _referenced_names(tree):
            for name, target in _resolve(chain, namespace, extra):
                if name.startswith("const:"):
                    name = f"const:{getattr(inspect.getmodule(obj), '__name__', '?')}.{chain[0]}"
                stack.append((name, target))
    total = hashlib.blake2b(repr(sorted(parts.items())).encode(), digest_size=16).hexdigest()
    return total, parts
