"""The registry of functions a pipeline may name.

A YAML file can only name functions registered here (by the project's ``stages.library`` modules or by a
module listed in the ``STAGES_PLUGINS`` environment variable): it cannot run arbitrary code.

A registered function declares its interface through its signature:

* positional (or positional-or-keyword) arguments are **inputs** wired in the YAML ``inputs:``; those with a
  default (``ground_truth=None``) are optional and may be left unwired;
* keyword-only arguments are **params**; their defaults and annotations give types for validation;
* the keyword-only names ``item_name`` (the item being processed) and ``out_dir`` (a folder for files the
  stage publishes, for ``writes_files=True``) are supplied by the engine.

Fan-out: ``"item"`` functions run once per item (``foreach:``), ``"pair"`` functions take two stacks
``A: (a, ...)`` and ``B: (b, ...)`` and return ``(a, b, ...)`` (``pairs:``, executed in tiles; ``mirror``
turns an (a,b,...) block into the (b,a,...) block), ``"once"`` functions run once.
"""
from __future__ import annotations

import importlib
import inspect
import os
import types
import typing
from dataclasses import dataclass, field
from typing import Any, Callable

ENGINE_ARGS = ("item_name", "out_dir")


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


_REGISTRY: dict[str, StageFunction] = {}
_LOADED = False


def register(name: str, fanout: str = "once", mirror: Callable | None = None, writes_files: bool = False,
             kind: str = "stage"):
    """Decorator: make ``func`` available to pipelines under ``name``.

    Args:
        name: the name YAML files use (``function: name``).
        fanout: "once", "item" or "pair".
        mirror: for "pair" functions, maps an (a,b,...) result block to its (b,a,...) transpose.
        writes_files: the function receives ``out_dir`` and the files it writes there are published to the
            pipeline's output folder.
        kind: "stage", or "generator" for functions that write a dataset folder (``generated:`` in YAML).
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
        if kind == "generator" and "out_dir" not in engine:
            raise TypeError(f"{name}: a generator takes out_dir")
        if name in _REGISTRY and _REGISTRY[name].func.__qualname__ != func.__qualname__:
            raise ValueError(f"function name {name!r} registered twice")
        _REGISTRY[name] = StageFunction(name, func, fanout, tuple(inputs), params, tuple(engine), mirror,
                                        tuple(optional), writes_files, kind, inspect.getdoc(func) or "")
        func.__stage_name__ = name
        return func

    return wrap


def load_library() -> None:
    """Import the project's stage modules and the allow-listed plugin modules (``STAGES_PLUGINS``)."""
    global _LOADED
    if _LOADED:
        return
    importlib.import_module("shapecorr")
    for mod in filter(None, (m.strip() for m in os.environ.get("STAGES_PLUGINS", "").split(","))):
        importlib.import_module(mod)
    _LOADED = True


def get(name: str) -> StageFunction:
    """The registered function ``name`` (KeyError if unknown)."""
    load_library()
    return _REGISTRY[name]


def names(kind: str | None = None) -> list[str]:
    """All registered names, optionally of one kind."""
    load_library()
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
