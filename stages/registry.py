"""The registry of functions a pipeline may name, and the plugins that register them.

A YAML file can only name registered functions: it cannot run arbitrary code. Functions are registered by
**plugins**, found through one mechanism, the Python entry point group ``stages.plugins``: an application
declares in its ``pyproject.toml``::

    [project.entry-points."stages.plugins"]
    myapp = "myapp:PLUGIN"

and the object it names is a :class:`Plugin`; importing its module registers the application's functions
(with :func:`register`). The plugin also declares which packages the code fingerprints follow, which package
versions the report lists, and the titles of the report groups its functions belong to.

For tests and development, the environment variable ``STAGES_PLUGINS`` (comma-separated ``module`` or
``module:attribute``) loads further plugins the same way; a module without a ``PLUGIN`` attribute counts as a
plugin whose code is that module. Nothing else is ever imported by name.

A registered function declares its interface through its signature:

* positional (or positional-or-keyword) arguments are **inputs** wired in the YAML ``inputs:``; those with a
  default (``ground_truth=None``) are optional and may be left unwired;
* keyword-only arguments are **params**; their defaults and annotations give types for validation;
* the keyword-only names ``item_name`` (the item being processed), ``out_dir`` (a folder for files the
  stage publishes, for ``writes_files=True``) and, for pair functions, ``pairs`` (the ``(p, 2)`` local index
  pairs of a stage on a candidate graph, see below) are supplied by the engine.

Fan-out: ``"item"`` functions run once per item (``foreach:``), ``"pair"`` functions take two stacks
``A: (a, ...)`` and ``B: (b, ...)`` and return ``(a, b, ...)`` (``pairs:``, executed in tiles; ``mirror``
turns an (a,b,...) block into the (b,a,...) block), ``"once"`` functions run once. A pair function that also
takes ``pairs=None`` can run on a candidate graph (``candidates:`` in YAML): it then receives ``pairs``, a
``(p, 2)`` int64 array of (row of A, row of B), and returns ``(p, ...)``, one value per pair.
"""
from __future__ import annotations

import importlib
import importlib.metadata
import inspect
import os
import threading
import types
import typing
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

from .errors import PipelineError

ENGINE_ARGS = ("item_name", "out_dir", "pairs")
ENTRY_POINT_GROUP = "stages.plugins"
PLUGINS_ENV = "STAGES_PLUGINS"


@dataclass(frozen=True)
class Measure:
    """One column of a headline table (see :class:`Headline`).

    Attributes:
        label: the column title.
        key: the dotted metric key of a cell (as ``stages.results.scalar_metrics`` flattens them); ``{row}`` is
            replaced by the row name. ``"@seconds_per_task"`` is the compute seconds per task of the stage that
            fed the row (the metrics stage's input named by :attr:`Headline.row_inputs`).
        better: "max" or "min" (the best value of the column is marked), or None.
        per_row: row -> key for rows whose value lives under another key.
        only_row: a metric key whose value names the one row this measure applies to (e.g. "solver").
        divide_by: a metric key the value is divided by (e.g. an upper bound).
    """
    label: str
    key: str
    better: str | None = "max"
    per_row: dict[str, str] = field(default_factory=dict)
    only_row: str | None = None
    divide_by: str | None = None


@dataclass(frozen=True)
class Headline:
    """A compact summary table the report shows first: rows (methods) x measures, best value marked.

    Attributes:
        group: the report group it summarises (a key of :attr:`Plugin.groups`).
        title: the table's title.
        rows: the row names (rows without any value are left out), or
        rows_from: a metric key whose dict keys are the rows (used when ``rows`` is empty).
        measures: the columns.
        row_inputs: row -> the input of the metrics stage that produced it (for ``@seconds_per_task``).
        figures: the figures that carry the result, as ``"function:file"`` (a file the stages running that
            registered function publish, e.g. ``"corr.evaluate:accuracy.png"``), shown next to the table.
    """
    group: str
    title: str
    measures: tuple[Measure, ...]
    rows: tuple[str, ...] = ()
    rows_from: str | None = None
    row_inputs: dict[str, str] = field(default_factory=dict)
    figures: tuple[str, ...] = ()


@dataclass
class Plugin:
    """What an application declares to the engine (the object its ``stages.plugins`` entry point names).

    Attributes:
        name: a short name (shown in errors and ``python -m stages functions``).
        packages: packages (or modules) whose code the fingerprints follow: a function, class or module
            constant in them that a stage function reaches is part of its cache key.
        report_packages: distribution names whose versions the report's provenance lists.
        groups: report group -> section title, in display order; a function registered with
            ``group=G`` has its figures shown in section G.
        headlines: the summary tables of the report (:class:`Headline`), in display order.
        sweep_metrics: the dotted metric keys ``sweep`` prints by default (and the report's sweep tables show);
            empty: the cells of the headline tables.
        modules: the modules whose import registers the plugin's functions, imported only when a function of
            the plugin is first looked up (see :func:`get`), so that a command on a pipeline of other plugins
            does not pay their import (a second for a plugin of plotting and scientific code). Empty: the
            plugin's own module registers everything when it is loaded.
        namespaces: with ``modules``: the first dotted part of every name the plugin registers (``"corr"`` for
            ``"corr.evaluate"``); looking up a name in one imports the plugin's modules. A name registered
            outside them is an error when the modules are imported.
        worker_warmup: what each worker process of a local cluster does when it starts, after importing
            ``modules``, for a pipeline that names the plugin: ``"module"`` (imported) or ``"module:function"``
            (called with no arguments), e.g. the heavy libraries the stage functions import on first use. The
            workers start while the client is still preparing the run (writing generated datasets), so this
            work is then off the first tasks' time. One that fails is skipped (the task that needs it reports).
    """
    name: str
    packages: tuple[str, ...] = ()
    report_packages: tuple[str, ...] = ()
    groups: dict[str, str] = field(default_factory=dict)
    headlines: tuple[Headline, ...] = ()
    sweep_metrics: tuple[str, ...] = ()
    modules: tuple[str, ...] = ()
    namespaces: tuple[str, ...] = ()
    worker_warmup: tuple[str, ...] = ()

    def owns(self, module: str) -> bool:
        """True when ``module`` is one of :attr:`packages` or inside one."""
        return any(module == p or module.startswith(p + ".") for p in self.packages)


@dataclass
class ParamSpec:
    """One declared parameter: its default (``REQUIRED`` if none) and annotation."""
    name: str
    default: Any
    annotation: Any

    @property
    def required(self) -> bool:
        return self.default is inspect.Parameter.empty


@dataclass
class StageFunction:
    """A function a pipeline stage may run."""
    name: str
    func: Callable
    fanout: str
    inputs: tuple[str, ...]
    params: dict[str, ParamSpec]
    engine_args: tuple[str, ...]
    mirror: Callable | None = None
    optional_inputs: tuple[str, ...] = ()
    writes_files: bool = False
    kind: str = "stage"  # "stage" or "generator"
    doc: str = field(default="")
    group: str | None = None   # report group (see Plugin.groups)
    module: str = ""           # the module that defines the function
    validate: Callable[..., Any] | None = None  # checks the params when the pipeline is read (see register)


_REGISTRY: dict[str, StageFunction] = {}
_PLUGINS: dict[str, Plugin] = {}
_UNIMPORTED: dict[str, Plugin] = {}   # namespace -> the plugin whose ``modules`` register it, not imported yet
_IMPORT_LOCK = threading.RLock()
_LOADED = False


def register(name: str, fanout: str = "once", mirror: Callable | None = None, writes_files: bool = False,
             kind: str = "stage", group: str | None = None, validate: Callable[..., Any] | None = None):
    """Decorator: make ``func`` available to pipelines under ``name``.

    Args:
        name: the name YAML files use (``function: name``).
        fanout: "once", "item" or "pair".
        mirror: for "pair" functions, maps an (a,b,...) result block to its (b,a,...) transpose.
        writes_files: the function receives ``out_dir`` and the files it writes there are published to the
            pipeline's output folder.
        kind: "stage", or "generator" for functions that write a dataset folder (``generated:`` in YAML).
        group: the report section of the stage's figures (a key of its plugin's ``groups``).
        validate: ``validate(**params)`` is called with a stage's (or generator's) params, defaults filled in,
            when the pipeline file is read, before anything runs. It raises ``ValueError`` (a message naming the
            parameter and the fix) for values the function cannot use, reported as a configuration error; it
            may return a list of warnings (values that run but give meaningless results).
    """
    if fanout not in ("once", "item", "pair"):
        raise ValueError(f"fanout must be once/item/pair, got {fanout!r}")

    def wrap(func: Callable) -> Callable:
        sig = inspect.signature(func)
        try:
            hints = typing.get_type_hints(func)
        except Exception:  # unresolvable annotations: validate by default value only
            hints = {}
        inputs, params, engine, optional = [], {}, [], []
        for p in sig.parameters.values():
            if p.name in ENGINE_ARGS:
                engine.append(p.name)
            elif p.kind == p.KEYWORD_ONLY:
                params[p.name] = ParamSpec(p.name, p.default, hints.get(p.name, Any))
            elif p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD):
                inputs.append(p.name)
                if p.default is not p.empty:
                    optional.append(p.name)
            else:
                raise TypeError(f"{name}: *args/**kwargs are not allowed in registered functions")
        if fanout == "pair" and inputs != ["A", "B"]:
            raise TypeError(f"{name}: a pair function takes exactly the inputs (A, B)")
        if "pairs" in engine and fanout != "pair":
            raise TypeError(f"{name}: only a pair function (fanout='pair') takes the engine argument 'pairs'")
        if kind == "generator" and "out_dir" not in engine:
            raise TypeError(f"{name}: a generator takes out_dir")
        if name in _REGISTRY and _REGISTRY[name].func.__qualname__ != func.__qualname__:
            raise ValueError(f"function name {name!r} registered twice")
        _REGISTRY[name] = StageFunction(name, func, fanout, tuple(inputs), params, tuple(engine), mirror,
                                        tuple(optional), writes_files, kind, inspect.getdoc(func) or "", group,
                                        func.__module__, validate)
        func.__stage_name__ = name
        return func

    return wrap


def load_plugin(spec: str) -> Plugin:
    """Import ``module`` or ``module:attribute`` and register the :class:`Plugin` it holds (``PLUGIN`` by
    default; a module without one is a plugin of its own code). Importing registers its functions."""
    module_name, _, attr = spec.strip().partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise PipelineError(f"cannot import plugin '{spec}': {exc}",
                            fix=f"install it, or fix {PLUGINS_ENV} / the '{ENTRY_POINT_GROUP}' entry point") from exc
    plugin = getattr(module, attr or "PLUGIN", None)
    if plugin is None and attr:
        raise PipelineError(f"plugin '{spec}': module {module_name} has no attribute '{attr}'",
                            fix="name a Plugin object, e.g. 'package:PLUGIN'")
    return add_plugin(plugin if plugin is not None else Plugin(module_name, packages=(module_name,)))


def add_plugin(plugin: Plugin) -> Plugin:
    """Record a plugin's declarations (its functions are registered by importing its modules)."""
    if not isinstance(plugin, Plugin):
        raise PipelineError(f"a plugin must be a stages.registry.Plugin, got {type(plugin).__name__}",
                            fix="declare PLUGIN = Plugin(name=..., packages=(...)) in the plugin's module")
    if bool(plugin.modules) != bool(plugin.namespaces):
        raise PipelineError(f"plugin '{plugin.name}' declares {'modules' if plugin.modules else 'namespaces'} "
                            f"without {'namespaces' if plugin.modules else 'modules'}",
                            fix="declare both (its functions are then imported when first named) or neither")
    _PLUGINS[plugin.name] = plugin
    for namespace in plugin.namespaces:
        _UNIMPORTED[namespace] = plugin
    return plugin


def _import_modules(plugin: Plugin) -> None:
    """Import the ``modules`` of a plugin that declares them (registering its functions), once; a module that
    cannot be imported is the same error at every look-up of the plugin's names, not an unknown name after the
    first."""
    with _IMPORT_LOCK:   # a cluster may be starting in a thread (execute.make_client reads imported_plugins)
        if not any(_UNIMPORTED.get(n) is plugin for n in plugin.namespaces):
            return
        before = set(_REGISTRY)
        for module_name in plugin.modules:
            try:
                importlib.import_module(module_name)
            except ImportError as exc:
                raise PipelineError(f"cannot import module {module_name} of plugin '{plugin.name}': {exc}",
                                    fix="install what it imports, or fix the plugin's `modules`") from exc
        for namespace in plugin.namespaces:
            _UNIMPORTED.pop(namespace, None)
    stray = sorted(n for n in set(_REGISTRY) - before if n.split(".")[0] not in plugin.namespaces)
    if stray:
        raise PipelineError(f"plugin '{plugin.name}' registers {stray[0]!r} outside its namespaces "
                            f"{', '.join(plugin.namespaces)}", fix="add its first dotted part to `namespaces`")


def _import_all() -> None:
    """Import every plugin's ``modules`` (all names are wanted: a listing, a suggestion)."""
    load_library()
    with _IMPORT_LOCK:
        waiting = list({p.name: p for p in _UNIMPORTED.values()}.values())
    for plugin in waiting:
        _import_modules(plugin)


def installed_plugins() -> list[importlib.metadata.EntryPoint]:
    """The entry points of the ``stages.plugins`` group (installed applications)."""
    return sorted(importlib.metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda ep: ep.name)


def load_library() -> None:
    """Load every installed plugin (entry points) and the ones listed in ``STAGES_PLUGINS``, once (a plugin that
    declares ``modules`` has them imported when one of its functions is first looked up)."""
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    for ep in installed_plugins():
        load_plugin(ep.value)
    for spec in filter(None, (m.strip() for m in os.environ.get(PLUGINS_ENV, "").split(","))):
        load_plugin(spec)


def plugins(functions: Iterable[str] | None = None) -> list[Plugin]:
    """The loaded plugins (those that registered one of ``functions``, when given), in load order."""
    load_library()
    if functions is None:
        return list(_PLUGINS.values())
    modules = {fn.module for fn in map(find, functions) if fn is not None}
    return [p for p in _PLUGINS.values() if any(p.owns(m) for m in modules)]


def fingerprint_packages() -> tuple[str, ...]:
    """Every package a loaded plugin declares for code fingerprints."""
    return tuple(dict.fromkeys(pkg for p in plugins() for pkg in p.packages))


def group_titles() -> dict[str, str]:
    """Report group -> title, merged over the loaded plugins in load order."""
    out: dict[str, str] = {}
    for p in plugins():
        for key, title in p.groups.items():
            out.setdefault(key, title)
    return out


def headlines(functions: Iterable[str] | None = None) -> list[Headline]:
    """The headline tables of the loaded plugins (those that registered one of ``functions``, when given)."""
    return [h for p in plugins(functions) for h in p.headlines]


def sweep_metrics(functions: Iterable[str] | None = None) -> list[str]:
    """The metric keys the plugins (those that registered one of ``functions``) want in sweep tables."""
    return list(dict.fromkeys(k for p in plugins(functions) for k in p.sweep_metrics))


def get(name: str) -> StageFunction:
    """The registered function ``name`` (KeyError if unknown); its plugin's ``modules`` are imported first
    when they are not yet."""
    load_library()
    plugin = None if name in _REGISTRY else _UNIMPORTED.get(name.split(".")[0])
    if plugin is not None:
        _import_modules(plugin)
    return _REGISTRY[name]


def find(name: Any, kind: str | None = None) -> StageFunction | None:
    """The registered function ``name`` (of ``kind``, when given), or None: a check that imports only the
    plugin the name belongs to, where :func:`names` would import them all."""
    try:
        fn = get(name) if isinstance(name, str) else None
    except KeyError:
        return None
    return fn if fn is not None and (kind is None or fn.kind == kind) else None


def imported_plugins() -> list[str]:
    """The names of the plugins declaring ``modules`` whose modules this process has imported (the ones its
    pipelines named): what a worker process it starts should import too."""
    load_library()
    with _IMPORT_LOCK:
        waiting = {p.name for p in _UNIMPORTED.values()}
    return [p.name for p in _PLUGINS.values() if p.modules and p.name not in waiting]


def import_plugins(plugin_names: Iterable[str]) -> None:
    """Import the ``modules`` of the loaded plugins named (see :func:`imported_plugins`)."""
    load_library()
    for name in plugin_names:
        plugin = _PLUGINS.get(name)
        if plugin is not None and plugin.modules:
            _import_modules(plugin)


def warm_up(plugin_names: Iterable[str]) -> None:
    """Do the ``worker_warmup`` of the loaded plugins named, each entry on its own; an entry that fails is
    skipped (the task that needs it then reports the error, with its traceback)."""
    load_library()
    for name in plugin_names:
        plugin = _PLUGINS.get(name)
        for entry in plugin.worker_warmup if plugin is not None else ():
            module_name, _, function = entry.partition(":")
            try:
                module = importlib.import_module(module_name)
                if function:
                    getattr(module, function)()
            except Exception:  # noqa: BLE001 -- only a head start: the task that needs it reports the error
                pass


def names(kind: str | None = None) -> list[str]:
    """All registered names, optionally of one kind."""
    _import_all()
    return sorted(n for n, f in _REGISTRY.items() if kind is None or f.kind == kind)


def check_type(value: Any, annotation: Any) -> bool:
    """True when ``value`` (from YAML) fits ``annotation`` (int fits float; Any fits all)."""
    if annotation is Any or annotation is inspect.Parameter.empty:
        return True
    origin = typing.get_origin(annotation)
    if origin is typing.Union or origin is types.UnionType:
        return any(check_type(value, a) for a in typing.get_args(annotation))
    if origin is typing.Literal:
        return value in typing.get_args(annotation)
    if annotation is type(None):
        return value is None
    if origin in (list, tuple):
        return isinstance(value, (list, tuple))
    if origin is dict:
        return isinstance(value, dict)
    if annotation in (list, tuple):
        return isinstance(value, (list, tuple))
    if annotation is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if annotation is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if isinstance(annotation, type):
        return isinstance(value, annotation)
    return True


def coerce(value: Any, annotation: Any) -> Any:
    """Canonical form of a valid param value: an int given for a float-only annotation becomes a float,
    so ``sigma=1`` and ``sigma: 1.0`` give the same cache key."""
    if isinstance(value, tuple):
        return list(value)
    if isinstance(value, bool) or not isinstance(value, int):
        return value
    options = typing.get_args(annotation) if typing.get_origin(annotation) in (typing.Union, types.UnionType) \
        else (annotation,)
    if float in options and int not in options:
        return float(value)
    return value


def describe_type(annotation: Any) -> str:
    """A short human name for an annotation."""
    if annotation is Any:
        return "any"
    if isinstance(annotation, type):
        return annotation.__name__
    return str(annotation).replace("typing.", "")
