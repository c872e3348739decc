"""Reading and validating pipeline files.

A pipeline file (YAML, read with ``yaml.safe_load`` semantics only) has the top-level keys::

    name: chairs                # used for the output folder and the run record
    cache: cache                # the store (default: ./cache)
    output: results/chairs      # published files (default: results/<name>)
    params:   {...}             # free-form tree; strings may reference ${a.b} and ${generated.X}
    generated: {X: {generator: NAME, params: {...}}}   # datasets the project writes itself
    datasets: {D: {files: GLOB} | {groups: GLOB, pattern: REGEX} | {file: PATH} | {folder: PATH},
               optional: false}
    stages:   {S: {function: NAME, foreach: D|S | pairs: D|S, tile: 32,
                   inputs: {arg: SOURCE | SOURCE[item] | SOURCE[*]}, params: {...}, metrics: false}}

Relative paths are relative to the current working directory. Every error names the file, the key
(with its line) and a fix.
"""
from __future__ import annotations

import copy
import difflib
import os
import re
from dataclasses import dataclass, field
from typing import Any

import yaml

from . import registry
from .errors import PipelineError

TOP_KEYS = {"name", "description", "cache", "output", "params", "generated", "datasets", "stages"}
STAGE_KEYS = {"function", "foreach", "pairs", "tile", "inputs", "params", "metrics", "description"}
DATASET_KINDS = ("files", "groups", "file", "folder")
DATASET_KEYS = set(DATASET_KINDS) | {"pattern", "optional", "description"}
_REF = re.compile(r"\$\{([^}]+)\}")
_INPUT = re.compile(r"^([A-Za-z_][\w\-]*)(?:\[([^\]]+)\])?$")


@dataclass
class InputRef:
    """Where a function input comes from: a stage or dataset, all of it or one item."""
    source: str
    item: str | None = None      # a specific item name
    whole: bool = False          # "SOURCE[*]": the whole collection even inside a foreach


@dataclass
class DatasetSpec:
    name: str
    kind: str                    # files | groups | file | folder
    path: str                    # after interpolation
    pattern: str | None = None
    optional: bool = False
    generated: str | None = None  # name of the generated entry this path lives in, if any


@dataclass
class StageSpec:
    name: str
    function: str
    fanout: str                  # once | item | pair
    over: str | None             # foreach / pairs target
    inputs: dict[str, InputRef]
    params: dict[str, Any]       # declared params with defaults filled in
    tile: int = 32
    metrics: bool = False


@dataclass
class GeneratedSpec:
    name: str
    generator: str
    params: dict[str, Any]
    path: str = ""               # set by the planner: cache/generated/<key>


@dataclass
class Pipeline:
    file: str
    name: str
    cache_dir: str
    output_dir: str
    params: dict[str, Any]
    generated: dict[str, GeneratedSpec]
    datasets: dict[str, DatasetSpec]
    stages: dict[str, StageSpec]          # topologically ordered
    raw: dict = field(default_factory=dict)
    overrides: list[str] = field(default_factory=list)


class _Lines:
    """Line numbers of keys in a YAML document: ``lines[("stages","mrf","params")] -> 12``."""

    def __init__(self, text: str):
        self.lines: dict[tuple, int] = {}
        try:
            node = yaml.compose(text, Loader=yaml.SafeLoader)
        except yaml.YAMLError:
            return
        self._walk(node, ())

    def _walk(self, node, path):
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                key = path + (k.value,)
                self.lines[key] = k.start_mark.line + 1
                self._walk(v, key)
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                self._walk(v, path + (i,))

    def get(self, *path) -> int | None:
        while path:
            if path in self.lines:
                return self.lines[path]
            path = path[:-1]
        return None


def _suggest(word: str, options) -> str:
    close = difflib.get_close_matches(str(word), list(options), n=3)
    return f"did you mean {', '.join(repr(c) for c in close)}?" if close else \
        f"known: {', '.join(sorted(map(str, options))) or '(none)'}"


def load_pipeline(path: str, overrides: list[str] | tuple = (), cache_dir: str | None = None,
                  output_dir: str | None = None) -> Pipeline:
    """Read, override, interpolate and validate a pipeline file.

    Args:
        path: the YAML file.
        overrides: ``key=value`` strings (``--set``): ``a.b=v`` sets ``params.a.b``;
            ``STAGE.PARAM=v`` sets a stage parameter. Values are parsed as YAML scalars.
    Raises:
        PipelineError: naming the file, key, line and a fix.
    """
    registry.load_library()
    if not os.path.isfile(path):
        raise PipelineError("pipeline file not found", file=path, fix="check the path (relative to the current folder)")
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise PipelineError(f"invalid YAML: {getattr(exc, 'problem', exc)}", file=path,
                            line=mark.line + 1 if mark else None,
                            fix="fix the YAML syntax (indentation, colons, quotes)") from None
    lines = _Lines(text)
    if not isinstance(raw, dict):
        raise PipelineError("a pipeline file must be a mapping with 'stages:'", file=path)
    raw = copy.deepcopy(raw)
    err = lambda msg, *key, fix=None: PipelineError(  # noqa: E731
        msg, file=path, key=".".join(map(str, key)) or None, line=lines.get(*key), fix=fix)

    for k in raw:
        if k not in TOP_KEYS:
            raise err(f"unknown top-level key '{k}'", k, fix=_suggest(k, TOP_KEYS))
    for section in ("params", "generated", "datasets", "stages"):
        raw.setdefault(section, {})
        if raw[section] is None:
            raw[section] = {}
        if not isinstance(raw[section], dict):
            raise err(f"'{section}' must be a mapping", section)
    if not raw["stages"]:
        raise err("the pipeline has no stages", "stages", fix="add a 'stages:' mapping")
    for name, st in raw["stages"].items():
        if not isinstance(st, dict):
            raise err("a stage must be a mapping with at least 'function:'", "stages", name)
        st.setdefault("params", {})
        if st["params"] is None:
            st["params"] = {}
    _apply_overrides(raw, overrides, path, err)

    name = str(raw.get("name") or os.path.splitext(os.path.basename(path))[0])
    pipe = Pipeline(file=os.path.abspath(path), name=name,
                    cache_dir=os.path.abspath(cache_dir or raw.get("cache") or "cache"),
                    output_dir=os.path.abspath(output_dir or raw.get("output") or os.path.join("results", name)),
                    params={}, generated={}, datasets={}, stages={}, raw=raw, overrides=list(overrides))
    resolver = _Resolver(raw["params"], pipe, err)
    pipe.generated = _read_generated(raw, err, resolver)
    pipe.params = resolver.resolve(raw["params"], ("params",))
    pipe.datasets = _read_datasets(raw, resolver, err)
    pipe.stages = _read_stages(raw, pipe, resolver, err)
    return pipe


def _apply_overrides(raw: dict, overrides, path, err) -> None:
    for ov in overrides:
        if "=" not in ov:
            raise PipelineError(f"--set '{ov}' is not key=value", file=path, fix="write e.g. --set mrf.sigma=0.5")
        key, _, text = ov.partition("=")
        try:
            value = yaml.safe_load(text) if text != "" else ""
        except yaml.YAMLError:
            value = text
        parts = key.strip().split(".")
        if parts[0] in raw["stages"] and len(parts) == 2:
            stage = raw["stages"][parts[0]]
            fn = stage.get("function")
            try:
                known = registry.get(fn).params if fn else {}
            except KeyError:
                known = {}
            if parts[1] not in known and parts[1] not in stage["params"]:
                raise PipelineError(f"--set {key}: stage '{parts[0]}' has no parameter '{parts[1]}'", file=path,
                                    key=key, fix=_suggest(parts[1], list(known) or stage["params"]))
            stage["params"][parts[1]] = value
            continue
        if parts[0] == "params":
            parts = parts[1:]
        node = raw["params"]
        for i, p in enumerate(parts):
            if not isinstance(node, dict) or p not in node:
                opts = list(node) if isinstance(node, dict) else []
                if i == 0:
                    opts += [f"{s}.<param>" for s in raw["stages"]]
                raise PipelineError(f"--set {key}: unknown parameter '{'.'.join(parts[:i + 1])}'", file=path,
                                    key=key, fix=_suggest(p, opts))
            if i == len(parts) - 1:
                node[p] = value
            else:
                node = node[p]


class _Resolver:
    """Resolves ``${a.b}`` references against the params tree and ``${generated.X}`` paths."""

    def __init__(self, params: dict, pipe: Pipeline, err):
        self.params, self.pipe, self.err = params, pipe, err
        self.generated_used: set[str] = set()

    def lookup(self, ref: str, where: tuple, seen: tuple = ()) -> Any:
        if ref in seen:
            raise self.err(f"parameter reference cycle: {' -> '.join(seen + (ref,))}", *where)
        parts = ref.split(".")
        if parts[0] == "generated":
            if len(parts) != 2 or parts[1] not in self.pipe.generated:
                raise self.err(f"unknown generated dataset '${{{ref}}}'", *where,
                               fix=_suggest(parts[-1], self.pipe.generated))
            self.generated_used.add(parts[1])
            return GeneratedPath(parts[1])
        node = self.params
        for p in parts:
            if not isinstance(node, dict) or p not in node:
                raise self.err(f"unknown parameter reference '${{{ref}}}'", *where,
                               fix=_suggest(p, node if isinstance(node, dict) else []))
            node = node[p]
        return self.resolve(node, where, seen + (ref,))

    def resolve(self, value: Any, where: tuple, seen: tuple = ()) -> Any:
        if isinstance(value, dict):
            return {k: self.resolve(v, where + (k,), seen) for k, v in value.items()}
        if isinstance(value, list):
            return [self.resolve(v, where, seen) for v in value]
        if isinstance(value, str):
            m = _REF.fullmatch(value.strip())
            if m:
                return self.lookup(m.group(1).strip(), where, seen)
            if _REF.search(value):
                return _REF.sub(lambda mm: str(self.lookup(mm.group(1).strip(), where, seen)), value)
        return value


class GeneratedPath(str):
    """Placeholder for the folder of a generated dataset; replaced by the planner."""

    def __new__(cls, name: str):
        obj = super().__new__(cls, f"@generated/{name}")
        obj.generated_name = name
        return obj


def _read_generated(raw: dict, err, resolver: "_Resolver") -> dict[str, GeneratedSpec]:
    out = {}
    for name, spec in raw["generated"].items():
        if not isinstance(spec, dict) or "generator" not in spec:
            raise err("a generated dataset needs 'generator:'", "generated", name,
                      fix=f"generators: {', '.join(registry.names('generator'))}")
        gen = spec["generator"]
        if gen not in registry.names("generator"):
            raise err(f"unknown generator '{gen}'", "generated", name, "generator",
                      fix=_suggest(gen, registry.names("generator")))
        params = resolver.resolve(dict(spec.get("params") or {}), ("generated", name, "params"))
        _check_params(registry.get(gen), params, err, ("generated", name, "params"))
        for k, v in params.items():
            if not registry.check_type(v, registry.get(gen).params[k].annotation):
                raise err(f"parameter '{k}' = {v!r} has the wrong type", "generated", name, "params", k)
            params[k] = registry.coerce(v, registry.get(gen).params[k].annotation)
        out[name] = GeneratedSpec(name, gen, _fill_defaults(registry.get(gen), params))
    return out


def _read_datasets(raw: dict, resolver: _Resolver, err) -> dict[str, DatasetSpec]:
    out = {}
    for name, spec in raw["datasets"].items():
        if not isinstance(spec, dict):
            raise err("a dataset must be a mapping like {files: 'folder/*.obj'}", "datasets", name)
        for k in spec:
            if k not in DATASET_KEYS:
                raise err(f"unknown dataset key '{k}'", "datasets", name, k, fix=_suggest(k, DATASET_KEYS))
        kinds = [k for k in DATASET_KINDS if k in spec]
        if len(kinds) != 1:
            raise err("a dataset needs exactly one of files/groups/file/folder", "datasets", name,
                      fix="e.g. files: ${data.root}/*.obj")
        kind = kinds[0]
        value = resolver.resolve(spec[kind], ("datasets", name, kind))
        if not isinstance(value, str):
            raise err(f"'{kind}' must be a path string", "datasets", name, kind)
        gen = None
        m = re.match(r"^@generated/([^/]+)", value)
        if m:
            gen = m.group(1)
        pattern = spec.get("pattern")
        if kind == "groups":
            if not pattern or "(?P<item>" not in pattern:
                raise err("a 'groups' dataset needs 'pattern:' with an (?P<item>...) group and usually an "
                          "(?P<index>...) group (files without an index form a group of one)",
                          "datasets", name, fix=r"pattern: '(?P<item>\d+)_(?P<index>\d+)\.png'")
            try:
                re.compile(pattern)
            except re.error as exc:
                raise err(f"invalid regular expression: {exc}", "datasets", name, "pattern") from None
        out[name] = DatasetSpec(name, kind, value, pattern, bool(spec.get("optional", False)), gen)
    return out


def _parse_input(text: Any, err, where) -> InputRef:
    if not isinstance(text, str):
        raise err("an input must be a name like 'hog', 'hog[*]' or 'meshes[mesh000]'", *where)
    m = _INPUT.match(text.strip())
    if not m:
        raise err(f"cannot read input reference '{text}'", *where, fix="use NAME, NAME[*] or NAME[item]")
    src, sel = m.group(1), m.group(2)
    return InputRef(src, None if sel in (None, "*") else sel, sel == "*")


def _check_params(fn: registry.StageFunction, params: dict, err, where: tuple) -> None:
    for k, v in params.items():
        if k not in fn.params:
            raise err(f"unknown parameter '{k}' for function '{fn.name}'", *where, k,
                      fix=_suggest(k, fn.params))
    for k, spec in fn.params.items():
        if k not in params and spec.required:
            raise err(f"missing required parameter '{k}' of function '{fn.name}'", *where,
                      fix=f"add '{k}:' under {'.'.join(map(str, where))}")


def _fill_defaults(fn: registry.StageFunction, params: dict) -> dict:
    out = {k: spec.default for k, spec in fn.params.items() if not spec.required}
    out.update(params)
    return out


def _read_stages(raw: dict, pipe: Pipeline, resolver: _Resolver, err) -> dict[str, StageSpec]:
    stages: dict[str, StageSpec] = {}
    names = set(raw["stages"]) | set(pipe.datasets)
    for name in raw["stages"]:
        if name in pipe.datasets:
            raise err(f"'{name}' is both a dataset and a stage", "stages", name, fix="rename one of them")
    for name, st in raw["stages"].items():
        for k in st:
            if k not in STAGE_KEYS:
                raise err(f"unknown stage key '{k}'", "stages", name, k, fix=_suggest(k, STAGE_KEYS))
        fname = st.get("function")
        if not fname:
            raise err("stage has no 'function:'", "stages", name, fix=_suggest("", registry.names("stage")))
        try:
            fn = registry.get(fname)
            if fn.kind != "stage":
                raise KeyError(fname)
        except KeyError:
            raise err(f"unknown function '{fname}'", "stages", name, "function",
                      fix=_suggest(fname, registry.names("stage"))) from None
        if "foreach" in st and "pairs" in st:
            raise err("a stage has either 'foreach:' or 'pairs:', not both", "stages", name)
        over = st.get("foreach") or st.get("pairs")
        fanout = "item" if "foreach" in st else "pair" if "pairs" in st else "once"
        if fanout != fn.fanout:
            want = {"item": "foreach: <dataset or stage>", "pair": "pairs: <dataset or stage>", "once": "no foreach/pairs"}
            raise err(f"function '{fname}' runs per {fn.fanout}, but the stage is declared per {fanout}",
                      "stages", name, fix=f"use {want[fn.fanout]}")
        if over is not None and over not in names:
            raise err(f"unknown dataset or stage '{over}'", "stages", name, "foreach" if fanout == "item" else "pairs",
                      fix=_suggest(over, names))
        inputs_raw = st.get("inputs") or {}
        if not isinstance(inputs_raw, dict):
            raise err("'inputs' must map argument names to sources", "stages", name, "inputs")
        inputs = {}
        for arg, ref in inputs_raw.items():
            if arg not in fn.inputs:
                raise err(f"function '{fname}' has no input '{arg}'", "stages", name, "inputs", arg,
                          fix=f"its inputs: {', '.join(fn.inputs) or '(none)'}")
            ref = resolver.resolve(ref, ("stages", name, "inputs", arg))
            inputs[arg] = _parse_input(ref, err, ("stages", name, "inputs", arg))
            if inputs[arg].source not in names:
                raise err(f"unknown dataset or stage '{inputs[arg].source}'", "stages", name, "inputs", arg,
                          fix=_suggest(inputs[arg].source, names))
        if fanout == "pair":
            inputs = {"A": InputRef(over), "B": InputRef(over)}
        for arg in fn.inputs:
            if arg not in inputs and arg not in fn.optional_inputs:
                raise err(f"input '{arg}' of function '{fname}' is not wired", "stages", name, "inputs",
                          fix=f"add 'inputs: {{{arg}: <dataset or stage>}}'")
        params = resolver.resolve(st.get("params") or {}, ("stages", name, "params"))
        _check_params(fn, params, err, ("stages", name, "params"))
        params = _fill_defaults(fn, params)
        for k, v in params.items():
            if isinstance(v, GeneratedPath):
                continue
            if not registry.check_type(v, fn.params[k].annotation):
                raise err(f"parameter '{k}' = {v!r} has the wrong type; '{fname}' expects "
                          f"{registry.describe_type(fn.params[k].annotation)}", "stages", name, "params", k)
            params[k] = registry.coerce(v, fn.params[k].annotation)
        tile = resolver.resolve(st.get("tile", 32), ("stages", name, "tile"))
        if not isinstance(tile, int) or isinstance(tile, bool) or tile < 1:
            raise err("'tile' must be a positive integer", "stages", name, "tile")
        stages[name] = StageSpec(name, fname, fanout, over, inputs, params, tile, bool(st.get("metrics", False)))
    return _toposort(stages, pipe, err)


def _toposort(stages: dict[str, StageSpec], pipe: Pipeline, err) -> dict[str, StageSpec]:
    deps = {n: sorted({r.source for r in s.inputs.values() if r.source in stages} |
                      ({s.over} if s.over in stages else set())) for n, s in stages.items()}
    order, state = [], {}

    def visit(n, trail):
        if state.get(n) == 2:
            return
        if state.get(n) == 1:
            cyc = trail[trail.index(n):] + [n]
            raise err(f"the stages form a cycle: {' -> '.join(cyc)}", "stages", n,
                      fix="a stage cannot depend (directly or indirectly) on itself")
        state[n] = 1
        for d in deps[n]:
            visit(d, trail + [n])
        state[n] = 2
        order.append(n)

    for n in stages:
        visit(n, [])
    return {n: stages[n] for n in order}
