"""Code fingerprints: a hash of a function's AST and of the project functions it uses.

Comments, docstrings and formatting do not change a fingerprint; a change to the function or to any
project function, class or module constant it reaches (transitively) does. "Project" is the function's own
module plus the packages the caller names (the plugins declare them, see ``registry.fingerprint_packages``);
other code is not followed: it is pinned by the package versions recorded in each run's provenance.
"""
from __future__ import annotations

import ast
import hashlib
import inspect
import os
import textwrap
import types
from typing import Any


def _is_project(obj: Any, project: frozenset) -> bool:
    """True when ``obj`` (a module, function or class) lives in one of the ``project`` modules or packages."""
    mod = getattr(obj, "__module__", None) if not isinstance(obj, types.ModuleType) else obj.__name__
    if not isinstance(mod, str) or not mod:
        return False
    parts = mod.split(".")
    return any(".".join(parts[:i]) in project for i in range(1, len(parts) + 1))


def _strip_docstrings(tree: ast.AST) -> ast.AST:
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Module)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant) \
                    and isinstance(body[0].value.value, str):
                node.body = body[1:] or [ast.Pass()]
    return tree


_MEMO: dict[int, tuple[Any, str, frozenset]] = {}
_DISK: dict = {"path": None, "table": {}, "dirty": False}


def use_disk_cache(path: str) -> None:
    """Keep digests across processes in ``path`` (JSON), keyed by source file, its size and mtime, and the
    object's name and line: a no-op run then parses no source at all."""
    if _DISK["path"] == path:
        return
    from .store import read_checked_json

    _DISK.update(path=path, dirty=False)
    table = read_checked_json(path, "fingerprinting the code again", default={})
    _DISK["table"] = {k: v for k, v in table.items() if isinstance(k, str)}


def save_disk_cache() -> None:
    """Write the digest cache if it changed (atomically)."""
    from .store import write_checked_json

    if _DISK["path"] and _DISK["dirty"]:
        try:
            write_checked_json(_DISK["path"], _DISK["table"])
        except OSError:  # a read-only cache: the table is only a speed-up
            pass
        _DISK["dirty"] = False


def _disk_key(obj: Any) -> str | None:
    try:
        path = inspect.getsourcefile(obj)
        st = os.stat(path)
        line = obj.__code__.co_firstlineno if hasattr(obj, "__code__") else ""
        return f"{path}:{st.st_size}:{st.st_mtime_ns}:{obj.__module__}.{obj.__qualname__}:{line}"
    except (TypeError, OSError, AttributeError):
        return None


def _digest_and_refs(obj: Any) -> tuple[str, frozenset]:
    """(AST digest, dotted names it references) of a function or class, memoized per object and on disk."""
    hit = _MEMO.get(id(obj))
    if hit is not None and hit[0] is obj:
        return hit[1], hit[2]
    key = _disk_key(obj) if _DISK["path"] else None
    if key is not None and key in _DISK["table"]:
        digest, refs_list = _DISK["table"][key]
        refs = frozenset(tuple(r) for r in refs_list)
    else:
        digest, tree = _ast_digest(obj)
        refs = frozenset(_referenced_names(tree)) if tree is not None else frozenset()
        if key is not None:
            _DISK["table"][key] = [digest, sorted(refs)]
            _DISK["dirty"] = True
    _MEMO[id(obj)] = (obj, digest, refs)
    return digest, refs


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


def _resolve(chain: tuple[str, ...], namespace: dict, project: frozenset) -> list[tuple[str, Any]]:
    """Project objects reached by a dotted name chain, with their qualified names."""
    if chain[0] not in namespace:
        return []
    obj, found = namespace[chain[0]], []
    for attr in chain[1:] + (None,):
        if isinstance(obj, types.ModuleType):
            if attr is None or not _is_project(obj, project):
                break
            if not hasattr(obj, attr):
                break
            obj = getattr(obj, attr)
            continue
        if _is_project(obj, project) and (inspect.isfunction(obj) or inspect.isclass(obj)):
            found.append((f"{obj.__module__}.{obj.__qualname__}", obj))
        elif isinstance(obj, (int, float, str, bytes, bool, tuple, frozenset, list, dict)) and len(chain) == 1:
            found.append((f"const:{chain[0]}", obj))
        break
    return found


def _constant_repr(obj: Any, held: list) -> str:
    """``repr`` of a constant that is the same in every process: a function or class inside it (a dispatch table
    such as ``{"a": step_a}``) is written by its qualified name, not by its address, and appended to ``held`` as
    (qualified name, object) so that its code is fingerprinted too."""
    if inspect.isfunction(obj) or inspect.isclass(obj):
        name = f"{obj.__module__}.{obj.__qualname__}"
        held.append((name, obj))
        return f"<{name}>"
    if isinstance(obj, dict):
        return "{" + ", ".join(f"{_constant_repr(k, held)}: {_constant_repr(v, held)}" for k, v in obj.items()) + "}"
    if isinstance(obj, (list, tuple)):
        return type(obj).__name__ + "(" + ", ".join(_constant_repr(v, held) for v in obj) + ")"
    if isinstance(obj, frozenset):
        return "frozenset(" + ", ".join(sorted(_constant_repr(v, held) for v in obj)) + ")"
    return repr(obj)


def code_fingerprint(func: Any, packages: tuple[str, ...] | frozenset = ()) -> tuple[str, dict[str, str]]:
    """Fingerprint ``func`` and every project function/class/constant it reaches.

    "Project" means ``packages`` (package or module names, e.g. ``("mylib", "myapp")``) plus the
    module that defines ``func`` (so helpers next to a plugin's stage function are tracked too).

    Returns:
        digest: one hex string over everything reached.
        parts: {qualified name: hex digest} of each reached project object (for "why will this rerun").
    """
    func = inspect.unwrap(func)
    project = frozenset(packages) | {func.__module__}
    parts: dict[str, str] = {}
    stack: list[tuple[str, Any]] = [(f"{func.__module__}.{func.__qualname__}", func)]
    while stack:
        qual, obj = stack.pop()
        if qual in parts:
            continue
        if qual.startswith("const:"):
            held: list[tuple[str, Any]] = []
            text = _constant_repr(obj, held)
            # plain constants keep repr(obj), so existing cache keys stay valid
            parts[qual] = hashlib.blake2b((text if held else repr(obj)).encode(), digest_size=8).hexdigest()
            stack.extend((name, f) for name, f in held if _is_project(f, project))
            continue
        digest, refs = _digest_and_refs(obj)
        parts[qual] = digest
        if not refs:
            continue
        namespace = dict(getattr(inspect.getmodule(obj), "__dict__", {}))
        if inspect.isfunction(obj) and obj.__closure__:
            namespace.update(zip(obj.__code__.co_freevars, (c.cell_contents for c in obj.__closure__)))
        for chain in refs:
            for name, target in _resolve(chain, namespace, project):
                if name.startswith("const:"):
                    name = f"const:{getattr(inspect.getmodule(obj), '__name__', '?')}.{chain[0]}"
                stack.append((name, target))
    total = hashlib.blake2b(repr(sorted(parts.items())).encode(), digest_size=16).hexdigest()
    return total, parts
