"""Code fingerprints: a hash of a function's AST and of the project code it can run.

Comments, docstrings and formatting do not change a fingerprint; a change to the function or to any project
function, class, module constant or module-level statement it reaches (transitively) does. "Project" is the
function's own module plus the packages the caller names (the plugins declare them, see
``registry.fingerprint_packages``); other code is not followed: it is pinned by the package versions recorded
in each run's provenance.

What counts as "reached" (each is a part, named in ``code_fingerprint``'s second result and in the reasons
``status`` prints):

* a name of the module's namespace, of a closure, or bound by an import *inside* the function body
  (``import m``, ``from m import f``, relative ``from .m import f``);
* an attribute chain through project modules and classes: ``mod.func``, ``mod.CONST``, ``mod.Class.method``
  (a class counts with its whole body, so every method of a class a stage instantiates is in);
* names in default argument values and in decorators (other than the stage function's own registration);
* the functions held in a constant (a dispatch table ``{"a": step_a}``, a ``functools.partial``);
* any other module-level value (an instance, a compiled pattern, a computed table): the module statements that
  assign it, and what they reach.

When a reference into the project cannot be resolved statically (a project module used as a value, an object
with no assignment statement), the whole module's source is the part (``module:NAME``): a spurious rerun is
acceptable, a stale hit is not. ``stages.audit`` checks the result by observation: every project function that
actually executes while a task runs must be covered by one of its parts.
"""
from __future__ import annotations

import ast
import functools
import hashlib
import importlib
import importlib.util
import inspect
import os
import sys
import textwrap
import types
from typing import Any

from .checksums import read_checked_json, write_checked_json


def _module_name(obj: Any) -> str | None:
    """The name of the module that defines ``obj`` (or of ``obj`` itself when it is a module)."""
    mod = obj.__name__ if isinstance(obj, types.ModuleType) else getattr(obj, "__module__", None)
    return mod if isinstance(mod, str) and mod else None


def _in_project(module: str | None, project: frozenset) -> bool:
    """True when the dotted module name is one of the ``project`` modules or packages, or inside one."""
    if not module:
        return False
    parts = module.split(".")
    return any(".".join(parts[:i]) in project for i in range(1, len(parts) + 1))


def _is_project(obj: Any, project: frozenset) -> bool:
    """True when ``obj`` (a module, function or class) lives in one of the ``project`` modules or packages."""
    return _in_project(_module_name(obj), project)


_WITH_DOCSTRING = (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Module)


def _without_docstring(body: list) -> list:
    """A statement list without its leading docstring (a lone docstring leaves ``pass``)."""
    if body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant) \
            and isinstance(body[0].value.value, str):
        return body[1:] or [ast.Pass()]
    return body


def _strip_docstrings(tree: ast.AST) -> ast.AST:
    """``tree`` with the docstring of each module, class and function removed, in place."""
    for node in ast.walk(tree):
        if isinstance(node, _WITH_DOCSTRING):
            node.body = _without_docstring(node.body)
    return tree


_MEMO: dict[Any, tuple[Any, str, frozenset]] = {}
_DISK: dict = {"path": None, "table": {}, "dirty": False}
# bump when what a part means changes, so that digests cached on disk by an older engine are not reused
_TABLE_VERSION = "2"


def use_disk_cache(path: str) -> None:
    """Keep digests across processes in ``path`` (JSON), keyed by source file, its size and mtime, and the
    object's name and line: a no-op run then parses no source at all."""
    if _DISK["path"] == path:
        return
    _DISK.update(path=path, dirty=False)
    table = read_checked_json(path, "fingerprinting the code again", default={})
    _DISK["table"] = {k: v for k, v in table.items() if isinstance(k, str)}


def save_disk_cache() -> None:
    """Write the digest cache if it changed (atomically)."""
    if _DISK["path"] and _DISK["dirty"]:
        try:
            write_checked_json(_DISK["path"], _DISK["table"])
        except OSError:  # a read-only cache: the table is only a speed-up
            pass
        _DISK["dirty"] = False


def _file_stamp(path: str | None) -> str | None:
    """``path:size:mtime_ns`` of a source file (None when it cannot be read)."""
    try:
        st = os.stat(path)
        return f"{path}:{st.st_size}:{st.st_mtime_ns}"
    except (TypeError, OSError):
        return None


def _disk_key(obj: Any) -> str | None:
    try:
        stamp = _file_stamp(inspect.getsourcefile(obj))
        line = obj.__code__.co_firstlineno if hasattr(obj, "__code__") else ""
        return stamp and f"v{_TABLE_VERSION}:{stamp}:{obj.__module__}.{obj.__qualname__}:{line}"
    except (TypeError, OSError, AttributeError):
        return None


def _memoized(memo_key: Any, disk_key: str | None, compute) -> tuple[str, frozenset]:
    """(digest, refs) from the process memo, the on-disk table or ``compute()`` (then stored in both).

    refs are tuples: a dotted name chain ('np', 'linalg', 'norm'), or ('import', alias, module, attr) for a
    binding made by an import statement inside the code (attr '' for ``import module``)."""
    hit = _MEMO.get(memo_key)
    if hit is not None:
        return hit[1], hit[2]
    if disk_key is not None and _DISK["path"] and disk_key in _DISK["table"]:
        digest, refs_list = _DISK["table"][disk_key]
        refs = frozenset(tuple(r) for r in refs_list)
    else:
        digest, refs = compute()
        if disk_key is not None and _DISK["path"]:
            _DISK["table"][disk_key] = [digest, sorted(refs)]
            _DISK["dirty"] = True
    _MEMO[memo_key] = (None, digest, refs)
    return digest, refs


def _digest_and_refs(obj: Any) -> tuple[str, frozenset]:
    """(AST digest, references) of a function or class, memoized per object and on disk."""
    hit = _MEMO.get(id(obj))
    if hit is not None and hit[0] is obj:
        return hit[1], hit[2]
    key = _disk_key(obj)

    def compute():
        digest, tree = _ast_digest(obj)
        return digest, (frozenset(_references(tree, _package_of(obj))) if tree is not None else frozenset())

    digest, refs = _memoized(("obj", key), key, compute) if key else compute()
    _MEMO[id(obj)] = (obj, digest, refs)  # holds obj, so its id is not reused while the entry lives
    return digest, refs


def _hash_tree(tree: ast.AST) -> str:
    return _hash_text(ast.dump(tree, include_attributes=False))


def _hash_text(text: str) -> str:
    return hashlib.blake2b(text.encode(), digest_size=16).hexdigest()


def _dump_without_docstrings(tree: ast.AST, *, undecorated: ast.AST | None = None) -> str:
    """``ast.dump(tree)`` (no attributes) of ``tree`` as ``_strip_docstrings`` would leave it, with the
    decorators of the node ``undecorated`` left out, without changing ``tree`` (a cached module's, shared)."""

    def text(node) -> str:
        if isinstance(node, ast.AST):
            cls = type(node)
            args = []
            for name in node._fields:
                try:
                    value = getattr(node, name)
                except AttributeError:
                    continue
                if value is None and getattr(cls, name, ...) is None:
                    continue
                if name == "body" and isinstance(node, _WITH_DOCSTRING):
                    value = _without_docstring(value)
                elif name == "decorator_list" and node is undecorated:
                    value = []
                args.append(f"{name}={text(value)}")
            return f"{cls.__name__}({', '.join(args)})"
        if isinstance(node, list):
            return f"[{', '.join(text(x) for x in node)}]"
        return repr(node)

    return text(tree)


def _ast_digest(obj: Any) -> tuple[str, ast.AST | None]:
    """Digest of ``obj``'s source without docstrings and without the decorators of the object itself (its
    registration is wiring, not computation); the tree returned keeps those decorators, so that a project
    decorator's code is followed.

    A definition at a module's top level is hashed from the module's parsed tree (the tree its own text would
    parse to); a nested one from its text, dedented as before (dedenting also changes the multi-line strings
    inside it)."""
    node, lines = _definition_node(obj)
    if node is not None and node.col_offset == 0:
        wrapped = ast.Module(body=[node], type_ignores=[])
        return _hash_text(_dump_without_docstrings(wrapped, undecorated=node)), wrapped
    try:
        src = textwrap.dedent(_definition_text(node, lines) if node is not None else inspect.getsource(obj))
        tree = _strip_docstrings(ast.parse(src))
        outer = next((node for node in ast.walk(tree)
                      if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))), None)
        decorators = outer.decorator_list if outer is not None else []
        if outer is not None:
            outer.decorator_list = []            # hashed without them (parsing once: half the planning time)
        try:
            digest = _hash_tree(tree)
        finally:
            if outer is not None:
                outer.decorator_list = decorators
        return digest, tree
    except (OSError, TypeError, SyntaxError):
        return _hash_text(repr(getattr(obj, "__code__", obj))), None


def _package_of(obj: Any) -> str:
    """The package relative imports inside ``obj`` are resolved against."""
    module = sys.modules.get(_module_name(obj) or "")
    return getattr(module, "__package__", None) or (_module_name(obj) or "").rpartition(".")[0]


def _references(tree: ast.AST, package: str) -> set[tuple[str, ...]]:
    """Maximal dotted name chains loaded in ``tree`` (``np.linalg.norm`` -> ('np','linalg','norm'), not also
    ('np',)), plus one ('import', alias, module, attr) per name an import statement in ``tree`` binds."""
    refs: set[tuple[str, ...]] = set()
    inner: set[int] = set()
    for node in ast.walk(tree):  # breadth first: an outer attribute is met before the chain inside it
        if isinstance(node, ast.Attribute):
            if id(node) in inner:
                continue
            parts, cur = [], node
            while isinstance(cur, ast.Attribute):
                inner.add(id(cur))
                parts.append(cur.attr)
                cur = cur.value
            if isinstance(cur, ast.Name):
                inner.add(id(cur))
                refs.add(tuple([cur.id] + parts[::-1]))
        elif isinstance(node, ast.Name) and id(node) not in inner:
            refs.add((node.id,))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname:
                    refs.add(("import", alias.asname, alias.name, ""))
                else:  # ``import a.b.c`` imports a.b.c and binds ``a``
                    refs.add(("import", alias.name.split(".")[0], alias.name, "^"))
        elif isinstance(node, ast.ImportFrom):
            base = "." * node.level + (node.module or "")
            try:
                module = importlib.util.resolve_name(base, package) if node.level else base
            except (ImportError, ValueError):
                module = base
            for alias in node.names:
                if alias.name != "*":
                    refs.add(("import", alias.asname or alias.name, module, alias.name))
    return refs


def _import_binding(module: str, attr: str, project: frozenset) -> Any:
    """The object an import statement binds: a module, or ``attr`` of it (itself a submodule when no such
    attribute exists), or with attr "^" the top package of ``module`` (``import a.b`` binds ``a``). Only
    project modules are imported here; others resolve to None (not followed)."""
    if attr == "^":
        if not _in_project(module, project):
            return None
        try:
            importlib.import_module(module)
        except Exception:  # noqa: BLE001 - the task itself will report the failing import
            return _Unresolved(module)
        return sys.modules[module.split(".")[0]]
    target = f"{module}.{attr}" if attr else module
    if not _in_project(module, project) and not _in_project(target, project):
        return None
    try:
        mod = importlib.import_module(module)
    except Exception:  # noqa: BLE001 - the task itself will report the failing import
        return _Unresolved(module)
    if not attr:
        return mod
    if hasattr(mod, attr):
        return getattr(mod, attr)
    try:
        return importlib.import_module(target)
    except Exception:  # noqa: BLE001
        return _Unresolved(module)


class _Unresolved:
    """A project reference that could not be followed: the whole module stands for it."""

    def __init__(self, module: str):
        self.module = module


def _module_tree(name: str) -> ast.Module | None:
    """The parsed source of module ``name`` (None when it has none readable), parsed once per file version."""
    return _module_source(name).tree


class _ModuleSource:
    """A module's source file as read once per file version: its lines (``splitlines(keepends=True)``), its
    parsed ``tree`` and, built on first use, the definitions by qualified name (``definitions``)."""

    def __init__(self, path: str | None, text: str | None):
        self.path = path
        self.lines = text.splitlines(keepends=True) if text is not None else []
        try:
            self.tree = ast.parse(text) if text is not None else None
        except (SyntaxError, ValueError):
            self.tree = None
        self._definitions: dict | None = None

    @property
    def definitions(self) -> dict[str, list[ast.AST]]:
        """{qualname: [function and class nodes with that ``__qualname__``, in source order]} (Python's own
        qualnames: ``C.method``, ``f.<locals>.g``; the order ``inspect``'s class search meets them in)."""
        if self._definitions is None:
            found: dict[str, list[ast.AST]] = {}
            if self.tree is not None:
                _collect_definitions(self.tree, [], found)
            self._definitions = found
        return self._definitions


_STATEMENT_LISTS = ("body", "orelse", "finalbody", "handlers", "cases")   # where a def or class statement can be


def _collect_definitions(node: ast.AST, stack: list[str], found: dict) -> None:
    """Add the def and class statements inside ``node`` to ``found`` under their qualnames (``stack``: the names
    around ``node``); only statement lists are searched, as a definition is a statement, in the order of the
    node's fields (``inspect``'s class search order: a ``try`` body, its handlers, ``else``, ``finally``)."""
    for field in node._fields:
        if field not in _STATEMENT_LISTS:
            continue
        for child in getattr(node, field):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                found.setdefault(".".join([*stack, child.name]), []).append(child)
                inner = [*stack, child.name] + ([] if isinstance(child, ast.ClassDef) else ["<locals>"])
                _collect_definitions(child, inner, found)
            elif isinstance(child, ast.AST):
                _collect_definitions(child, stack, found)


def _module_source(name: str) -> _ModuleSource:
    """``_ModuleSource`` of module ``name`` (no lines and no tree when it has no readable source)."""
    path = getattr(sys.modules.get(name), "__file__", None)
    key = ("tree", name, _file_stamp(path))
    if key not in _TREES:
        try:
            source_path = inspect.getsourcefile(sys.modules[name])
            with open(source_path, encoding="utf-8") as f:
                _TREES[key] = _ModuleSource(source_path, f.read())
        except (KeyError, TypeError, OSError, ValueError):
            _TREES[key] = _ModuleSource(None, None)
    return _TREES[key]


_TREES: dict[tuple, _ModuleSource] = {}


def _source(obj: Any) -> str:
    """The source text of a function or class, giving the AST ``inspect.getsource(obj)`` gives: cut from its
    module's lines, parsed once per file (``inspect`` tokenizes every function's text and parses the whole module
    again for every class, the larger part of planning); ``inspect.getsource`` itself when the definition is not
    found there unambiguously (a lambda, a function made at run time, a file changed since its import).

    Raises OSError or TypeError as ``inspect.getsource``."""
    node, lines = _definition_node(obj)
    return _definition_text(node, lines) if node is not None else inspect.getsource(obj)


def _definition_text(node: ast.AST, lines: list[str]) -> str:
    """The lines of a def or class node of a module, from its first decorator to its end."""
    return "".join(lines[_first_line(node) - 1:node.end_lineno])


def _first_line(node: ast.AST) -> int:
    """The line a def or class statement starts on: its first decorator's (``co_firstlineno`` of a function)."""
    return min([node.lineno] + [d.lineno for d in node.decorator_list])


def _definition_node(obj: Any) -> tuple[ast.AST | None, list[str]]:
    """(the def or class node ``inspect.getsource`` would read for ``obj``, its module's lines), or (None, [])."""
    try:
        obj = inspect.unwrap(obj)                     # as inspect.getsourcelines
    except ValueError:
        return None, []
    qualname, module = getattr(obj, "__qualname__", None), getattr(obj, "__module__", None)
    if not isinstance(qualname, str) or not isinstance(module, str) or module not in sys.modules:
        return None, []
    source = _module_source(module)
    if source.tree is None:
        return None, []
    candidates = source.definitions.get(qualname, [])
    if inspect.isclass(obj):                          # inspect takes the first class of that qualname
        classes = [n for n in candidates if isinstance(n, ast.ClassDef)]
        return (classes[0], source.lines) if classes else (None, [])
    code = getattr(obj, "__code__", None)
    if code is None or code.co_filename != source.path:
        return None, []
    functions = [n for n in candidates if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
                 and _first_line(n) == code.co_firstlineno]
    return (functions[0], source.lines) if len(functions) == 1 else (None, [])


def _module_digest(name: str) -> str:
    """Digest of a whole module's source (docstrings and comments excluded)."""
    stamp = _file_stamp(getattr(sys.modules.get(name), "__file__", None))

    def compute():
        tree = _module_tree(name)
        if tree is None:
            return _hash_text(f"unreadable:{name}"), frozenset()
        return _hash_text(_dump_without_docstrings(tree)), frozenset()

    return _memoized(("module", name, stamp), stamp and f"v{_TABLE_VERSION}:{stamp}:module:{name}", compute)[0]


def _assigning_statements(tree: ast.Module, name: str) -> list[ast.stmt]:
    """The top-level statements of a module that bind ``name`` (assignments, augmented assignments, loops,
    with-blocks and conditionals that contain one)."""
    found = []
    for stmt in tree.body:
        if isinstance(stmt, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Import, ast.ImportFrom)):
            continue
        for node in ast.walk(stmt):
            targets = node.targets if isinstance(node, ast.Assign) else \
                [node.target] if isinstance(node, (ast.AnnAssign, ast.AugAssign, ast.For, ast.NamedExpr)) else []
            if any(isinstance(t, ast.Name) and t.id == name for tgt in targets for t in ast.walk(tgt)):
                found.append(stmt)
                break
    return found


def _statement_digest_and_refs(module: str, name: str, package: str) -> tuple[str, frozenset] | None:
    """(digest, references) of the module statements that assign ``name``; None when there is none."""
    stamp = _file_stamp(getattr(sys.modules.get(module), "__file__", None))

    def compute():
        tree = _module_tree(module)
        stmts = _assigning_statements(tree, name) if tree is not None else []
        if not stmts:
            return "", frozenset()
        block = ast.Module(body=stmts, type_ignores=[])
        return _hash_tree(block), frozenset(_references(block, package))

    digest, refs = _memoized(("stmt", module, name, stamp), stamp and f"v{_TABLE_VERSION}:{stamp}:stmt:{module}.{name}",
                             compute)
    return (digest, refs) if digest else None


_SCALARS = (int, float, complex, str, bytes, bool, type(None))


def _is_value_constant(obj: Any) -> bool:
    """An immutable constant written by its repr: a scalar, or a tuple / frozenset of such values and of
    functions and classes (held by name). Mutable containers are read from their statements instead: their
    content may change at run time (a module-level cache), their statement does not."""
    if isinstance(obj, _SCALARS):
        return True
    if isinstance(obj, (tuple, frozenset)):
        return all(_is_value_constant(v) or inspect.isfunction(v) or inspect.isclass(v) for v in obj)
    return False


def _resolve(chain: tuple[str, ...], namespace: dict, home: str, project: frozenset) -> list[tuple[str, Any]]:
    """Project parts reached by a dotted name chain looked up in ``namespace`` (the globals of module ``home``,
    with closure and import bindings), as (part name, object) pairs.

    Part names: ``mod.qualname`` (a function or class), ``const:mod.NAME`` (an immutable value, by its repr),
    ``stmt:mod.NAME`` (the statements assigning any other module-level value), ``module:mod`` (a whole module)."""
    if chain[0] not in namespace:
        return []
    obj, owner, attr_name = namespace[chain[0]], home, chain[0]
    for attr in chain[1:] + (None,):
        obj = _unwrapped(obj)
        if isinstance(obj, _Unresolved):
            return [(f"module:{obj.module}", obj.module)]
        if isinstance(obj, types.ModuleType):
            if not _is_project(obj, project):
                return []
            if attr is None:  # a project module used as a value (getattr(mod, name), passed on): all of it
                return [(f"module:{obj.__name__}", obj.__name__)]
            value = getattr(obj, attr) if hasattr(obj, attr) else _import_binding(obj.__name__, attr, project)
            if value is None or isinstance(value, _Unresolved):
                return [(f"module:{obj.__name__}", obj.__name__)]
            obj, owner, attr_name = value, obj.__name__, attr
            continue
        if inspect.isfunction(obj) or inspect.isclass(obj):
            return [(f"{obj.__module__}.{obj.__qualname__}", obj)] if _is_project(obj, project) else []
        if _is_value_constant(obj):
            return [(f"const:{owner}.{attr_name}", obj)] if _in_project(owner, project) else []
        if _in_project(owner, project):  # any other value bound at module level in the project
            return [(f"stmt:{owner}.{attr_name}", (owner, attr_name, obj))]
        if _is_project(type(obj), project):  # an instance of a project class held elsewhere
            cls = type(obj)
            return [(f"{cls.__module__}.{cls.__qualname__}", cls)]
        return []
    return []


def _unwrapped(obj: Any) -> Any:
    """The function or class a decorator wrapped (``functools.lru_cache``, ``functools.wraps``), else ``obj``:
    the wrapper is not project code, what it calls is."""
    if isinstance(obj, types.ModuleType) or inspect.isfunction(obj) or inspect.isclass(obj):
        return obj
    try:
        if getattr(obj, "__wrapped__", None) is None:
            return obj
        inner = inspect.unwrap(obj)
    except Exception:  # noqa: BLE001 - an object whose attributes cannot be read is left as it is
        return obj
    return inner if inspect.isfunction(inner) or inspect.isclass(inner) else obj


def _imported_name(tree: ast.Module, name: str, package: str) -> tuple[str, str] | None:
    """(module, attribute) when a top-level ``from module import attribute [as name]`` binds ``name``."""
    for stmt in tree.body:
        if isinstance(stmt, ast.ImportFrom):
            base = "." * stmt.level + (stmt.module or "")
            try:
                module = importlib.util.resolve_name(base, package) if stmt.level else base
            except (ImportError, ValueError):
                continue
            for alias in stmt.names:
                if (alias.asname or alias.name) == name:
                    return module, alias.name
    return None


def _statement_parts(module: str, name: str, value: Any, project: frozenset) -> tuple[str | None, list]:
    """(digest, parts to follow) of a module-level value that is neither a function, a class nor an immutable
    constant: the statements of ``module`` that assign ``name`` and what they reach; for a name the module
    imports, the same in the module it comes from; otherwise (no statement) the whole module when the value's
    class is a project class, else nothing (a third-party object: pinned by package versions)."""
    package = getattr(sys.modules.get(module), "__package__", None) or module.rpartition(".")[0]
    found = _statement_digest_and_refs(module, name, package)
    if found is not None:
        digest, refs = found
        namespace = dict(getattr(sys.modules.get(module), "__dict__", {}))
        _bind_imports(namespace, refs, project)
        return digest, _reached(refs, namespace, module, project)
    tree = _module_tree(module)
    origin = _imported_name(tree, name, package) if tree is not None else None
    if origin is not None and _in_project(origin[0], project):
        return "import", [(f"stmt:{origin[0]}.{origin[1]}", (origin[0], origin[1], value))]
    cls = type(value)
    if _is_project(cls, project):
        return "instance", [(f"{cls.__module__}.{cls.__qualname__}", cls), (f"module:{module}", module)]
    return None, []


def _bind_imports(namespace: dict, refs: frozenset, project: frozenset) -> None:
    """Add to ``namespace`` the project objects that the import statements among ``refs`` bind."""
    for ref in refs:
        if ref[0] == "import" and len(ref) == 4:
            bound = _import_binding(ref[2], ref[3], project)
            if bound is not None:
                namespace[ref[1]] = bound


def _reached(refs: frozenset, namespace: dict, home: str, project: frozenset) -> list[tuple[str, Any]]:
    """The project parts the name chains among ``refs`` reach in ``namespace`` (see :func:`_resolve`)."""
    return [part for chain in refs if chain[0] != "import" for part in _resolve(chain, namespace, home, project)]


def _constant_repr(obj: Any, held: list) -> str:
    """``repr`` of a constant that is the same in every process: a function or class inside it (a dispatch table
    such as ``{"a": step_a}``, a ``functools.partial``) is written by its qualified name, not by its address,
    and appended to ``held`` as (qualified name, object) so that its code is fingerprinted too."""
    if inspect.isfunction(obj) or inspect.isclass(obj):
        name = f"{obj.__module__}.{obj.__qualname__}"
        held.append((name, obj))
        return f"<{name}>"
    if isinstance(obj, functools.partial):
        return (f"partial({_constant_repr(obj.func, held)}, {_constant_repr(obj.args, held)}, "
                f"{_constant_repr(dict(sorted(obj.keywords.items())), held)})")
    if isinstance(obj, dict):
        return "{" + ", ".join(f"{_constant_repr(k, held)}: {_constant_repr(v, held)}" for k, v in obj.items()) + "}"
    if isinstance(obj, (list, tuple)):
        return type(obj).__name__ + "(" + ", ".join(_constant_repr(v, held) for v in obj) + ")"
    if isinstance(obj, (frozenset, set)):
        return type(obj).__name__ + "(" + ", ".join(sorted(_constant_repr(v, held) for v in obj)) + ")"
    return repr(obj)


def _namespace(obj: Any, refs: frozenset, project: frozenset) -> dict:
    """The names ``obj``'s code sees: its module's globals, its closure and the bindings of the imports inside
    it (project modules only)."""
    namespace = dict(getattr(inspect.getmodule(obj), "__dict__", {}))
    if inspect.isfunction(obj) and obj.__closure__:
        for name, cell in zip(obj.__code__.co_freevars, obj.__closure__):
            try:
                namespace[name] = cell.cell_contents
            except ValueError:  # an empty cell (a name assigned later)
                pass
    _bind_imports(namespace, refs, project)
    return namespace


def code_fingerprint(func: Any, packages: tuple[str, ...] | frozenset = ()) -> tuple[str, dict[str, str]]:
    """Fingerprint ``func`` and every project function, class, constant and module statement it reaches.

    "Project" means ``packages`` (package or module names, e.g. ``("mylib", "myapp")``) plus the
    module that defines ``func`` (so helpers next to a plugin's stage function are tracked too).

    Returns:
        digest: one hex string over everything reached.
        parts: {part name: hex digest} of each reached project object (for "why will this rerun"); part
            names are described in :func:`_resolve`.
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
            # plain constants keep repr(obj), so their digest does not depend on how they are written
            parts[qual] = hashlib.blake2b((text if held else repr(obj)).encode(), digest_size=8).hexdigest()
            stack.extend((name, f) for name, f in held if _is_project(f, project))
            continue
        if qual.startswith("module:"):
            parts[qual] = _module_digest(obj)
            continue
        if qual.startswith("stmt:"):
            digest, follow = _statement_parts(*obj[:2], obj[2], project)
            if digest is not None:
                parts[qual] = digest
            stack.extend(follow)
            continue
        digest, refs = _digest_and_refs(obj)
        parts[qual] = digest
        if not refs:
            continue
        home = getattr(inspect.getmodule(obj), "__name__", "?")
        stack.extend(_reached(refs, _namespace(obj, refs, project), home, project))
    total = hashlib.blake2b(repr(sorted(parts.items())).encode(), digest_size=16).hexdigest()
    return total, parts
