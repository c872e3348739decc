"""Reading and validating pipeline files.

A pipeline file (YAML, read with ``yaml.safe_load`` semantics only) has the top-level keys::

    name: chairs                # used for the output folder and the run record
    cache: cache                # the store (default: ./cache)
    output: results/chairs      # published files (default: results/<name>)
    params:   {...}             # free-form tree; strings may reference ${a.b} and ${generated.X}
    generated: {X: {generator: NAME, params: {...}}}   # datasets the project writes itself
    datasets: {D: {files: GLOB} | {groups: GLOB, pattern: REGEX} | {file: PATH} | {folder: PATH},
               optional: false}
    stages:   {S: {function: NAME, foreach: D|S | pairs: D|S, tile: 32, candidates: S,
                   inputs: {arg: SOURCE | SOURCE[item] | SOURCE[*]}, params: {...}, metrics: false}}

Relative paths are relative to the current working directory. Every error names the file, the key
(with its line) and a fix.
"""
from __future__ import annotations

import copy
import difflib
import inspect
import os
import re
from dataclasses import dataclass, field
from typing import Any

import yaml

from . import registry
from .cache_root import cache_location, expand_path
from .errors import PipelineError, UserError, warn_once
from .yaml_strict import YAMLRefused, parse_yaml

TOP_KEYS = {"name", "description", "cache", "output", "params", "generated", "datasets", "stages"}
STAGE_KEYS = {"function", "foreach", "pairs", "tile", "candidates", "inputs", "params", "metrics", "description"}
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
    item_param: str | None = None  # the parameter the item name came from ("SOURCE[${template}]": "template")


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
    candidates: str | None = None  # pair stages on a candidate graph: the once stage that returns the pairs


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


MAX_EXPANDED = 1_000_000  # characters and values one ${...} reference (or a string holding some) may expand to


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
    text = _read_text(path)
    try:
        raw, lines = parse_yaml(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise PipelineError(f"invalid YAML: {getattr(exc, 'problem', exc)}", file=path,
                            line=mark.line + 1 if mark else None,
                            fix=None if isinstance(exc, YAMLRefused)
                            else "fix the YAML syntax (indentation, colons, quotes)") from None
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
    for section in ("stages", "datasets", "generated"):
        for key in raw[section]:
            _check_name(key, err, (section, key), what={"stages": "a stage", "datasets": "a dataset",
                                                        "generated": "a generated dataset"}[section])
    for name, st in raw["stages"].items():
        if not isinstance(st, dict):
            raise err("a stage must be a mapping with at least 'function:'", "stages", name)
        st.setdefault("params", {})
        if st["params"] is None:
            st["params"] = {}
    _apply_overrides(raw, overrides, path, err)

    for key in ("cache", "output", "name"):
        if raw.get(key) is not None and not isinstance(raw[key], str):
            raise err(f"'{key}' must be a string", key)
    if raw.get("name"):
        name = _check_name(raw["name"], err, ("name",), what="the pipeline")
    else:  # from the file name, made a plain identifier
        name = re.sub(r"[^A-Za-z0-9_\-]", "_", os.path.splitext(os.path.basename(path))[0]).lstrip("-") or "pipeline"
    def expanded(given: str | None, key: str, option: str) -> str | None:  # ~ and $VAR, as a shell would
        text = given or raw.get(key)
        try:
            return expand_path(text) if text else None
        except ValueError as exc:
            if given:
                raise UserError(f"{option}: {exc}", fix="set the variable, or write the folder out") from None
            raise err(str(exc), key, fix="set the variable, or write the folder out") from None

    pipe = Pipeline(file=os.path.abspath(path), name=name,
                    cache_dir=cache_location(expanded(cache_dir, "cache", "--cache") or "cache"),
                    output_dir=os.path.abspath(expanded(output_dir, "output", "--out")
                                               or os.path.join("results", name)),
                    params={}, generated={}, datasets={}, stages={}, raw=raw, overrides=list(overrides))
    resolver = _Resolver(raw["params"], pipe, err)
    pipe.generated = _read_generated(raw, err, resolver)
    pipe.params = resolver.resolve(raw["params"], ("params",))
    pipe.datasets = _read_datasets(raw, resolver, err)
    pipe.stages = _read_stages(raw, pipe, resolver, err)
    return pipe


MAX_PIPELINE_BYTES = 4 * 2**20
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")


def _check_name(name: Any, err, where: tuple, what: str) -> str:
    """``name`` if it is a plain identifier (letters, digits, '_' and '-', not starting with a digit or '-'):
    names become file and folder names under the output folder and the cache, so no '/', '..' or spaces."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise err(f"{what} name {name!r} is not a plain identifier", *where,
                  fix="use letters, digits, '_' and '-' only (e.g. align_export); names become folder names")
    return name


def _read_text(path: str) -> str:
    """The pipeline file as text; PipelineError when it is missing, unreadable, huge or not UTF-8 text."""
    if not os.path.isfile(path):
        raise PipelineError("pipeline file not found", file=path, fix="check the path (relative to the current folder)")
    try:
        if os.path.getsize(path) > MAX_PIPELINE_BYTES:
            raise PipelineError(f"the file is larger than {MAX_PIPELINE_BYTES // 2**20} MiB: not a pipeline file",
                                file=path, fix="pass the pipeline's YAML file")
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise PipelineError(f"cannot read the file: {exc.strerror or exc}", file=path,
                            fix="check the path and its permissions") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = None
    if text is None or "\x00" in text:
        raise PipelineError("not a text file (a pipeline file is YAML text in UTF-8)", file=path,
                            fix="pass the pipeline's YAML file, e.g. pipeline.yaml") from None
    return text


def _settable_keys(raw: dict) -> dict[str, str]:
    """Every key ``--set`` accepts in this pipeline -> where it acts: each pipeline parameter (dotted, e.g.
    ``humans.root``) with the stages whose settings refer to it, and each stage function parameter
    (``stage.param``)."""
    out: dict[str, str] = {}

    def leaves(node, prefix):
        for k, v in node.items():
            if isinstance(v, dict) and v:
                yield from leaves(v, f"{prefix}{k}.")
            else:
                yield f"{prefix}{k}"

    for name in leaves(raw.get("params") or {}, ""):
        users = [s for s, spec in raw["stages"].items() if "${" + name + "}" in str(spec)]
        out[name] = (f"pipeline parameter, used by stage{'s' if len(users) > 1 else ''} {', '.join(users)}"
                     if users else "pipeline parameter, used by the datasets" if "${" + name + "}" in
                     str(raw.get("datasets")) else "pipeline parameter")
    for stage, spec in raw["stages"].items():
        fn = spec.get("function") if isinstance(spec, dict) else None
        try:
            params = registry.get(fn).params if fn else {}
        except KeyError:
            params = {}
        for p in list(params) + [p for p in (spec.get("params") or {}) if p not in params]:
            out[f"{stage}.{p}"] = f"parameter of stage '{stage}' ({fn})"
    return out


def _suggest_key(key: str, raw: dict, fallback: str = "") -> str:
    """The closest keys ``--set`` accepts to ``key``, each with the stage it acts on: the keys ending in the
    same parameter name first (``solve.sigma_scale`` -> ``align.sigma_scale``), then the closest spellings."""
    keys = _settable_keys(raw)
    last = key.rsplit(".", 1)[-1]
    same_name = [k for k in keys if k.rsplit(".", 1)[-1] == last and k != key]
    close = difflib.get_close_matches(key, list(keys), n=4, cutoff=0.6)
    picked = list(dict.fromkeys(same_name + close))[:5]
    if not picked:
        return fallback or _suggest(key, keys)
    return "did you mean " + "; ".join(f"{k} ({keys[k]})" for k in picked) + "?"


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
                                    key=key, fix=_suggest_key(key.strip(), raw))
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
                                    key=key, fix=_suggest_key(key.strip(), raw, _suggest(p, opts)))
            if i == len(parts) - 1:
                node[p] = value
            else:
                node = node[p]


class _Resolver:
    """Resolves ``${a.b}`` references against the params tree and ``${generated.X}`` paths."""

    def __init__(self, params: dict, pipe: Pipeline, err):
        self.params, self.pipe, self.err = params, pipe, err
        self.generated_used: set[str] = set()
        self._done: dict[str, Any] = {}       # ref -> its resolved value (each parameter is resolved once)
        self._sizes: dict[int, tuple[int, Any]] = {}  # id(list or dict built here) -> (size, the object)

    def _size(self, value: Any) -> int:
        """Characters of the strings plus number of values in ``value`` once written out (linear: the size of
        every list and dict built here is remembered, so shared references are not walked again)."""
        if isinstance(value, str):
            return len(value)
        if isinstance(value, (dict, list)):
            hit = self._sizes.get(id(value))
            if hit is not None and hit[1] is value:
                return hit[0]
            n = 1 + sum(self._size(v) for v in (value.values() if isinstance(value, dict) else value))
            self._sizes[id(value)] = (n, value)
            return n
        return 1

    def _bounded(self, value: Any, what: str, where: tuple) -> Any:
        if self._size(value) > MAX_EXPANDED:
            raise self.err(f"{what} expands to more than {MAX_EXPANDED:,} characters and values (references "
                           "that repeat references, nested too deep?)", *where,
                           fix="write the value out, or reference it fewer times")
        return value

    def lookup(self, ref: str, where: tuple, seen: tuple = ()) -> Any:
        if ref in self._done:  # a copy: whoever gets a list or dict may change it
            return copy.deepcopy(self._done[ref]) if isinstance(self._done[ref], (dict, list)) else self._done[ref]
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
        value = self._bounded(self.resolve(node, where, seen + (ref,)), f"'${{{ref}}}'", where)
        self._done[ref] = value
        return copy.deepcopy(value) if isinstance(value, (dict, list)) else value

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
                return self._interpolate(value, where, seen)
        return value

    def _interpolate(self, value: str, where: tuple, seen: tuple) -> Any:
        """A string with ``${...}`` inside: references replaced by their text. A generated dataset's folder
        may only start the string (``${generated.X}/sub/*.obj``); the result is then a GeneratedPath."""
        head: GeneratedPath | None = None
        text, pos = [], 0
        for mm in _REF.finditer(value):
            got = self.lookup(mm.group(1).strip(), where, seen)
            text.append(value[pos:mm.start()])
            pos = mm.end()
            if isinstance(got, GeneratedPath):
                if mm.start() != 0:
                    raise self.err(f"'{value}': a generated dataset's folder can only start a path", *where,
                                   fix="write it as '${generated.NAME}/sub/path'")
                head = got
            else:
                text.append(str(got))
            if sum(map(len, text)) > MAX_EXPANDED:
                break   # reported below
        text.append(value[pos:])
        rest = self._bounded("".join(text), f"'{value[:60]}'", where)
        return head.joined(rest) if head is not None else rest


class GeneratedPath(str):
    """A path inside the folder of a generated dataset (``cache/generated/<key>``, known to the planner only):
    the dataset's name and the path ``rest`` below its folder ("" for the folder itself). As text it reads
    ``@generated/<name>/<rest>`` (what messages show)."""

    generated_name: str
    rest: str

    def __new__(cls, name: str, rest: str = ""):
        rest = rest.lstrip("/")
        obj = super().__new__(cls, f"@generated/{name}" + (f"/{rest}" if rest else ""))
        obj.generated_name, obj.rest = name, rest
        return obj

    def __getnewargs__(self):  # copy/pickle rebuild from (name, rest), not from the text
        return self.generated_name, self.rest

    def joined(self, suffix: str) -> "GeneratedPath":
        """This path with ``suffix`` appended as text: ``(chairs, "")`` + ``"/*"`` -> ``(chairs, "*")``."""
        return GeneratedPath(self.generated_name, self.rest + suffix)

    def under(self, folder: str) -> str:
        """The real path once the dataset's folder is known."""
        return os.path.join(folder, self.rest) if self.rest else folder


def _read_generated(raw: dict, err, resolver: "_Resolver") -> dict[str, GeneratedSpec]:
    out = {}
    for name, spec in raw["generated"].items():
        if not isinstance(spec, dict) or "generator" not in spec:
            raise err("a generated dataset needs 'generator:'", "generated", name,
                      fix=f"generators: {', '.join(registry.names('generator'))}")
        gen = spec["generator"]
        if registry.find(gen, "generator") is None:
            raise err(f"unknown generator '{gen}'", "generated", name, "generator",
                      fix=_suggest(gen, registry.names("generator")))
        params = resolver.resolve(dict(spec.get("params") or {}), ("generated", name, "params"))
        _check_params(registry.get(gen), params, err, ("generated", name, "params"))
        for k, v in params.items():
            if not registry.check_type(v, registry.get(gen).params[k].annotation):
                raise err(f"parameter '{k}' = {v!r} has the wrong type", "generated", name, "params", k)
            params[k] = registry.coerce(v, registry.get(gen).params[k].annotation)
        params = _fill_defaults(registry.get(gen), params)
        _validate_params(registry.get(gen), params, err, ("generated", name, "params"))
        out[name] = GeneratedSpec(name, gen, params)
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
        empty = _empty_references(spec[kind], resolver, ("datasets", name, kind))
        if empty:
            if not spec.get("optional", False):
                raise err(f"'{kind}' uses {', '.join('${' + r + '}' for r in empty)}, which is empty",
                          "datasets", name, kind, fix=f"set it, e.g. --set {empty[0]}=FOLDER")
            value = ""  # an optional dataset that is not given: the stages that need it are skipped
        gen = value.generated_name if isinstance(value, GeneratedPath) else None
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


def _empty_references(text: Any, resolver: "_Resolver", where: tuple) -> list[str]:
    """The ``${...}`` references in ``text`` whose value is empty ("" or null)."""
    if not isinstance(text, str):
        return []
    refs = [m.strip() for m in _REF.findall(text)]
    return [r for r in refs if not r.startswith("generated.") and resolver.lookup(r, where) in ("", None)]


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


def _validate_params(fn: registry.StageFunction, params: dict, err, where: tuple) -> None:
    """Run the function's own check of its params (``register(validate=...)``): ValueError -> PipelineError;
    returned strings are printed as warnings naming the stage."""
    check = getattr(fn, "validate", None)
    if check is None:
        return
    if any(isinstance(v, GeneratedPath) for v in params.values()):
        return  # paths are filled in by the planner; the function checks them when it runs
    try:
        warnings = check(**params) or []
    except (ValueError, TypeError) as exc:
        raise err(str(exc), *where, fix=f"change the value under {'.'.join(map(str, where))} (or the --set)") from None
    for w in warnings:
        warn_once(f"{'.'.join(map(str, where))}: {w}")


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
        fn = registry.find(fname, "stage")
        if fn is None:
            raise err(f"unknown function '{fname}'", "stages", name, "function",
                      fix=_suggest(fname, registry.names("stage")))
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
            param = re.fullmatch(r"\s*[\w.-]+\[\$\{([^}]+)\}\]\s*", ref) if isinstance(ref, str) else None
            empty = _empty_references(ref, resolver, ("stages", name, "inputs", arg))
            if empty:
                raise err(f"input '{ref}' uses {', '.join('${' + r + '}' for r in empty)}, which is empty",
                          "stages", name, "inputs", arg, fix=f"set it, e.g. --set {empty[0]}=NAME")
            ref = resolver.resolve(ref, ("stages", name, "inputs", arg))
            inputs[arg] = _parse_input(ref, err, ("stages", name, "inputs", arg))
            if param:
                inputs[arg].item_param = param.group(1).strip()
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
        _validate_params(fn, params, err, ("stages", name, "params"))
        tile = resolver.resolve(st.get("tile", 32), ("stages", name, "tile"))
        if not isinstance(tile, int) or isinstance(tile, bool) or tile < 1:
            raise err("'tile' must be a positive integer", "stages", name, "tile")
        candidates = _read_candidates(st, name, fn, fanout, raw["stages"], names, resolver, err)
        stages[name] = StageSpec(name, fname, fanout, over, inputs, params, tile, bool(st.get("metrics", False)),
                                 candidates)
    return _toposort(stages, pipe, err)


def _read_candidates(st: dict, name: str, fn: registry.StageFunction, fanout: str, raw_stages: dict,
                     names: set[str], resolver: "_Resolver", err) -> str | None:
    """The ``candidates:`` stage of pair stage ``name`` (None without one), checked: only with ``pairs:``, a
    once stage, and a pair function that takes the engine argument ``pairs``."""
    fixed = ("give the pair function a keyword-only argument 'pairs=None': it receives (p, 2) int64 local "
             "index pairs (row of A, row of B) and returns (p, ...), one value per pair")
    if "candidates" not in st:
        if "pairs" in fn.engine_args and inspect.signature(fn.func).parameters["pairs"].default is inspect.Parameter.empty:
            raise err(f"function '{fn.name}' needs candidate pairs (its argument 'pairs' has no default)",
                      "stages", name, fix="add 'candidates: <once stage returning the pairs>', or give 'pairs' "
                                          "the default None")
        return None
    cand = resolver.resolve(st["candidates"], ("stages", name, "candidates"))
    if fanout != "pair":
        raise err("'candidates:' is only for pair stages (with 'pairs:')", "stages", name, "candidates",
                  fix="remove 'candidates:' or declare the stage with 'pairs: <dataset or stage>'")
    if not isinstance(cand, str) or cand not in names:
        raise err(f"unknown stage '{cand}'", "stages", name, "candidates", fix=_suggest(str(cand), set(raw_stages)))
    if cand not in raw_stages:
        raise err(f"'{cand}' is a dataset; 'candidates:' names a stage that returns the pairs", "stages", name,
                  "candidates", fix="name a once stage returning {'names': [...], 'pairs': (P, 2) int indices}")
    cand_function = (raw_stages[cand] or {}).get("function") if isinstance(raw_stages[cand], dict) else None
    cand_fn = registry.find(cand_function, "stage")
    cand_fanout = cand_fn.fanout if cand_fn is not None else "once"
    if cand_fanout != "once":  # an unknown function is reported at its own stage
        raise err(f"stage '{cand}' runs per {cand_fanout}; the candidates stage must run once", "stages", name,
                  "candidates", fix="name a once stage returning {'names': [...], 'pairs': (P, 2) int indices}")
    if "pairs" not in fn.engine_args:
        raise err(f"function '{fn.name}' cannot run on candidate pairs: it has no argument 'pairs'",
                  "stages", name, "candidates", fix=fixed)
    return cand


def _toposort(stages: dict[str, StageSpec], pipe: Pipeline, err) -> dict[str, StageSpec]:
    deps = {n: sorted({r.source for r in s.inputs.values() if r.source in stages} |
                      ({s.over} if s.over in stages else set()) |
                      ({s.candidates} if s.candidates in stages else set())) for n, s in stages.items()}
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
