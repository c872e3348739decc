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


# ---- everything a stage can run is in its key: the ways code is reached besides a module-level name ----

PKG = "fp_pkg"


@pytest.fixture
def package(tmp_path, monkeypatch):
    """``make(files, **edits)``: write ``files`` ({relative path: source, ``{pkg}`` standing for the package
    name}) as package ``fp_pkg`` in a folder of its own (so that versions never share modules or bytecode),
    after applying ``edits`` ({file stem: (old, new)}), and import its module ``main``."""
    from stages import fingerprint

    monkeypatch.setitem(fingerprint._DISK, "path", None)

    def forget():
        for mod in [m for m in sys.modules if m == PKG or m.startswith(PKG + ".")]:
            sys.modules.pop(mod)

    def make(files: dict[str, str], **edits: tuple[str, str]):
        forget()
        folder = tmp_path / uuid.uuid4().hex[:8]
        for rel, src in {"__init__.py": "", **files}.items():
            if rel[:-3] in edits:
                old, new = edits[rel[:-3]]
                assert old in src, (rel, old)
                src = src.replace(old, new)
            (folder / PKG / rel).parent.mkdir(parents=True, exist_ok=True)
            (folder / PKG / rel).write_text(textwrap.dedent(src).replace("{pkg}", PKG))
        sys.path.insert(0, str(folder))
        try:
            return importlib.import_module(f"{PKG}.main")
        finally:
            sys.path.remove(str(folder))

    yield make
    forget()


def fp(main):
    return code_fingerprint(main.stage, (PKG,))


LOCAL_IMPORTS = {
    "main.py": '''
        def stage(x):
            from .helpers import double          # relative, inside the body
            import {pkg}.absolute as absolute    # absolute, aliased
            from {pkg} import other              # a submodule by from-import
            return double(x) + absolute.plus_one(x) + other.OFFSET
        ''',
    "helpers.py": "def double(x):\n    return 2 * x\n",
    "absolute.py": "def plus_one(x):\n    return x + 1\n",
    "other.py": "OFFSET = 3\n",
}


def test_imports_inside_a_function_body_are_followed(package):
    base, parts = fp(package(LOCAL_IMPORTS))
    assert f"{PKG}.helpers.double" in parts            # from .helpers import double
    assert f"{PKG}.absolute.plus_one" in parts         # import pkg.absolute as absolute; absolute.plus_one
    assert f"const:{PKG}.other.OFFSET" in parts        # from pkg import other; other.OFFSET
    assert fp(package(LOCAL_IMPORTS))[0] == base       # the same code again: the same key
    for stem, edit in (("helpers", ("2 * x", "3 * x")), ("absolute", ("x + 1", "x + 2")),
                       ("other", ("OFFSET = 3", "OFFSET = 4"))):
        assert fp(package(LOCAL_IMPORTS, **{stem: edit}))[0] != base, stem


ATTRIBUTES = {
    "main.py": '''
        from . import settings
        from .model import Model
        import {pkg}.tables

        def stage(x, scale=settings.default_scale):
            m = Model(settings.FACTOR)
            return m.apply(x) * scale + {pkg}.tables.WEIGHTS[0]
        ''',
    "settings.py": "FACTOR = 2.0\n\ndef unused():\n    return 1.0\n\ndefault_scale = 1.5\n",
    "model.py": '''
        from .ops import square

        class Model:
            def __init__(self, factor):
                self.factor = factor

            def apply(self, x):
                return square(x) * self.factor
        ''',
    "ops.py": "def square(x):\n    return x * x\n",
    "tables.py": "import numpy as np\n\nWEIGHTS = np.array([1.0, 2.0])\n",
}


def test_module_attributes_methods_and_defaults_are_followed(package):
    base, parts = fp(package(ATTRIBUTES))
    assert f"const:{PKG}.settings.FACTOR" in parts and f"const:{PKG}.settings.default_scale" in parts
    assert f"{PKG}.model.Model" in parts and f"{PKG}.ops.square" in parts   # a method's helper
    assert f"stmt:{PKG}.tables.WEIGHTS" in parts                               # a computed module value
    for stem, edit in (("settings", ("FACTOR = 2.0", "FACTOR = 2.5")),
                       ("settings", ("default_scale = 1.5", "default_scale = 1.0")),
                       ("model", ("square(x) * self.factor", "square(x) + self.factor")),
                       ("ops", ("x * x", "x ** 3")),
                       ("tables", ("[1.0, 2.0]", "[1.5, 2.0]"))):
        assert fp(package(ATTRIBUTES, **{stem: edit}))[0] != base, (stem, edit)
    # a function of the module that nothing reaches still does not count
    assert fp(package(ATTRIBUTES, settings=("return 1.0", "return 2.0")))[0] == base


PARTIALS = {
    "main.py": '''
        import functools
        from .steps import step_a, step_b

        STEPS = {"a": functools.partial(step_a, k=2), "b": step_b}

        def stage(x, name="a"):
            return STEPS.get(name)(x)
        ''',
    "steps.py": "def step_a(x, k):\n    return x + k\n\ndef step_b(x):\n    return x * 2\n",
}


def test_functions_held_in_partials_of_a_dispatch_table_are_followed(package):
    base, parts = fp(package(PARTIALS))
    assert f"{PKG}.steps.step_a" in parts and f"{PKG}.steps.step_b" in parts
    assert fp(package(PARTIALS))[0] == base
    assert fp(package(PARTIALS, steps=("x + k", "x - k")))[0] != base
    assert fp(package(PARTIALS, main=("k=2", "k=3")))[0] != base


def test_a_project_module_used_as_a_value_counts_as_a_whole(package):
    files = {"main.py": "from . import impl\n\ndef stage(x, how='twice'):\n    return getattr(impl, how)(x)\n",
             "impl.py": "def twice(x):\n    return 2 * x\n"}
    base, parts = fp(package(files))
    assert f"module:{PKG}.impl" in parts
    assert fp(package(files, impl=("2 * x", "3 * x")))[0] != base


def test_the_audit_sees_a_function_the_fingerprint_cannot(package):
    """By observation: a call the source does not show (through the module's globals) is reported."""
    from stages import audit

    files = {"main.py": '''
        def hidden(x):
            return x + 1

        def stage(x):
            return globals()["hid" + "den"](x)
        '''}
    main = package(files)
    with audit.CallRecorder() as rec:
        main.stage(1)
    assert audit.uncovered(rec.executed(), fp(main)[1], frozenset({PKG})) == [f"{PKG}.main.hidden"]
    # what the fingerprint follows is covered, methods and nested functions by their class or function
    main = package(ATTRIBUTES)
    with audit.CallRecorder() as rec:
        main.stage(2.0)
    assert {"Model.__init__", "Model.apply", "square"} <= {q for _, q in rec.executed()}
    assert audit.uncovered(rec.executed(), fp(main)[1], frozenset({PKG})) == []


def test_a_cached_helper_is_followed_through_its_decorator(package):
    files = {"main.py": '''
        import functools

        @functools.lru_cache(maxsize=4)
        def table(n):
            return tuple(range(n))

        def stage(x):
            return x + sum(table(3))
        '''}
    base, parts = fp(package(files))
    assert f"{PKG}.main.table" in parts
    assert fp(package(files, main=("range(n)", "range(1, n)")))[0] != base


def test_the_audit_stops_watching_a_thread_that_outlives_it(package):
    """A thread started while recording (e.g. by a cluster starting alongside a generator) and still running
    after the recorder exits: what it calls afterwards is not recorded, and reading the record while it runs
    does not fail (it used to: "dictionary changed size during iteration")."""
    import threading

    from stages import audit

    main = package({"main.py": '''
        def during(x):
            return x + 1

        def after(x):
            return x + 2
        '''})
    inside, exited, done = threading.Event(), threading.Event(), threading.Event()

    def worker():
        main.during(1)
        inside.set()
        exited.wait()
        for i in range(2000):           # fresh code objects: each would be a new entry in the record
            namespace = {}
            exec(compile(f"def f{i}():\n    return {i}\n", __file__, "exec"), namespace)
            namespace[f"f{i}"]()
        main.after(1)
        done.set()

    with audit.CallRecorder() as rec:
        thread = threading.Thread(target=worker, daemon=True)
        thread.start()
        inside.wait()
    exited.set()
    while not done.is_set():
        rec.executed()
    thread.join()
    names = {q for _, q in rec.executed()}
    assert "during" in names and "after" not in names and "f1999" not in names


# ---- the source of a definition, cut from its module's parsed file ----------------------------------------------
TRICKY = '''
import functools

def deco(f):
    @functools.wraps(f)
    def wrapper(*a):
        return f(*a)
    return wrapper

if SWITCH:
    def chosen(x):
        return x + 1
else:
    def chosen(x):
        return x + 2

@deco
@functools.lru_cache(maxsize=None)
def decorated(x):
    return x * 3          # a trailing comment
    # and a comment line in the block

class Outer:
    """Outer."""
    class Inner:
        @staticmethod
        def method(y):
            text = """
a string whose lines start at column 0
"""
            return y, text

    def method(self):
        return 1

def factory():
    def made(z):
        return z - 1
    return made

SQUARE = lambda v: v * v

try:
    pass
except ValueError:
    class Twin:           # never defined, but inspect's search meets it first (a try's handlers before its else)
        A = 1
else:
    class Twin:
        A = 2
'''


def _project_definitions():
    """Every function and class defined in the project packages (methods included)."""
    import inspect
    import pkgutil

    found = []
    for package in ("stages", "corr_core", "shapecorr"):
        root = importlib.import_module(package)
        names = [package] + [m.name for m in pkgutil.walk_packages(root.__path__, package + ".")
                             if not m.name.endswith("__main__")]
        for name in names:
            holders = [importlib.import_module(name)]
            while holders:
                holder = holders.pop()
                for value in vars(holder).values():
                    if (inspect.isfunction(value) or inspect.isclass(value)) and value.__module__ == name \
                            and value not in found:
                        found.append(value)
                        if inspect.isclass(value):
                            holders.append(value)
    return found


def _tree(text: str) -> str:
    """The AST the fingerprint hashes from a source text, or the error that sends it to its fallback (a string
    at column 0 inside a method defeats the dedent, with either text)."""
    import ast

    try:
        return ast.dump(ast.parse(textwrap.dedent(text)))
    except SyntaxError as e:
        return f"{type(e).__name__}: {e.msg}"


def _digest_from_text(obj, text: str):
    """(digest, references) of ``obj`` from ``text``, its ``inspect.getsource``, the fingerprint's way before it
    read definitions from parsed modules: dedented and parsed, docstrings stripped, the object's own decorators
    left out of the digest; None when the text does not parse."""
    import ast

    from stages import fingerprint

    try:
        tree = fingerprint._strip_docstrings(ast.parse(textwrap.dedent(text)))
    except SyntaxError:
        return None
    outer = tree.body[0]
    decorators, outer.decorator_list = outer.decorator_list, []
    digest = fingerprint._hash_tree(tree)
    outer.decorator_list = decorators
    return digest, fingerprint._references(tree, fingerprint._package_of(obj))


def test_every_project_definition_is_read_and_hashed_as_from_inspects_text_and_modules_stay_as_parsed():
    """For every function and class of the project: the source cut from its module parses to the tree of
    ``inspect.getsource``'s text, and its digest and references (top-level definitions are hashed from the
    module's tree, without a copy) are those of that text; every module's digest is that of its file, and its
    cached tree is left as parsed."""
    import ast
    import inspect
    import sys

    from stages import fingerprint

    definitions = _project_definitions()
    cut = [d for d in definitions if fingerprint._definition_node(d)[0] is not None]
    assert len(definitions) > 1000 and len(cut) > 0.8 * len(definitions), (len(definitions), len(cut))
    differ = []
    for d in definitions:
        try:
            text = inspect.getsource(d)
        except (OSError, TypeError):              # dataclass-made methods: no source
            continue
        source = fingerprint._source(d)
        if source != text and _tree(source) != _tree(text):       # the same text parses to the same tree
            differ.append(f"source of {d.__module__}.{d.__qualname__}")
        expected = _digest_from_text(d, text)
        digest, tree = fingerprint._ast_digest(d)
        if expected is not None and (digest, fingerprint._references(tree, fingerprint._package_of(d))) != expected:
            differ.append(f"digest of {d.__module__}.{d.__qualname__}")
    assert not differ, differ
    for name in sorted({d.__module__ for d in definitions}):
        with open(sys.modules[name].__file__, encoding="utf-8") as f:
            text = f.read()
        digest = fingerprint._module_digest(name)
        assert ast.dump(fingerprint._module_tree(name)) == ast.dump(ast.parse(text)), name
        assert digest == fingerprint._hash_tree(fingerprint._strip_docstrings(ast.parse(text))), name


@pytest.mark.parametrize("switch", [True, False])
def test_the_source_cut_from_the_module_is_inspects_for_redefined_decorated_nested_and_made_definitions(
        load, switch):
    import inspect

    from stages.fingerprint import _definition_node, _source

    mod = load(f"SWITCH = {switch}\n" + TRICKY)
    objects = [mod.deco, mod.chosen, mod.decorated, mod.Outer, mod.Outer.Inner, mod.Outer.Inner.method,
               mod.Outer.method, mod.factory, mod.factory(), mod.SQUARE, mod.Twin]
    for obj in objects:
        assert _tree(_source(obj)) == _tree(inspect.getsource(obj)), obj
    assert "x + 1" in _source(mod.chosen) if switch else "x + 2" in _source(mod.chosen)
    assert _definition_node(mod.decorated)[0] is not None      # found through functools.wraps
    assert _definition_node(mod.factory())[0] is not None      # factory.<locals>.made
    assert _definition_node(mod.SQUARE)[0] is None             # a lambda: inspect's own search


def test_a_function_whose_file_changed_since_its_import_gets_inspects_source(load):
    """The file on disk moved the definition: the line no longer matches, so ``inspect.getsource`` answers."""
    import inspect
    import os

    from stages.fingerprint import _source

    mod = load("SWITCH = True\n" + TRICKY)
    path = mod.__file__
    text = open(path).read()
    with open(path, "w") as f:
        f.write("# a new first line\n" + text.replace("return x * 3", "return x * 4"))
    os.utime(path, ns=(1, 1))                     # another stamp, whatever the clock
    assert _tree(_source(mod.decorated)) == _tree(inspect.getsource(mod.decorated))
