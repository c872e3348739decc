"""Generated datasets: folders the project writes itself (``generated:`` in a pipeline file), once per
generator, code and parameters, into ``cache/generated/<key>``.

Planning only *looks*: :func:`resolve_generated` gives each generated dataset its folder, substitutes the
paths of those already complete and reports the others as pending (their stages are planned once ``run``
has written them). Only :func:`write_generated` (called by ``run`` and ``sweep``) executes generators.

A complete folder is sealed: its ``.complete`` record lists the checksum of every file (see
``store.seal_folder``); an edited, added-to or damaged folder counts as not generated and is written again.
"""
from __future__ import annotations

import dataclasses
import os
import shutil
from typing import Any, Callable

from . import audit, registry
from .blas import one_blas_thread
from .config import GeneratedPath, GeneratedSpec, Pipeline
from .fingerprint import code_fingerprint
from .checksums import digest_json
from .errors import warn_once
from .seal import check_folder, seal_folder
from .store import Store

KEY_VERSION = 1


def generated_key(gen: GeneratedSpec) -> str:
    """The folder name of a generated dataset: hash of generator name, its code fingerprint and params."""
    fn = registry.get(gen.generator)
    code, _ = code_fingerprint(fn.func, registry.fingerprint_packages())
    return digest_json({"v": KEY_VERSION, "generator": gen.generator, "code": code, "params": gen.params})


def generated_names_used(pipe: Pipeline) -> list[str]:
    """The generated datasets that a dataset path or a stage parameter refers to."""
    found: set[str] = set()

    def scan(value: Any) -> None:
        if isinstance(value, GeneratedPath):
            found.add(value.generated_name)
        elif isinstance(value, dict):
            for v in value.values():
                scan(v)
        elif isinstance(value, list):
            for v in value:
                scan(v)

    scan([ds.path for ds in pipe.datasets.values()])
    scan([st.params for st in pipe.stages.values()])
    return sorted(found)


def _substitute(value: Any, folders: dict[str, str]) -> Any:
    """``value`` with every GeneratedPath of a dataset in ``folders`` replaced by its real path."""
    if isinstance(value, GeneratedPath):
        return value.under(folders[value.generated_name]) if value.generated_name in folders else value
    if isinstance(value, dict):
        return {k: _substitute(v, folders) for k, v in value.items()}
    if isinstance(value, list):
        return [_substitute(v, folders) for v in value]
    return value


def resolve_generated(pipe: Pipeline, store: Store, digest: Callable[[str], str]) -> tuple[Pipeline, dict[str, str]]:
    """A copy of ``pipe`` whose generated datasets have their folder (``GeneratedSpec.path``) and whose
    paths into complete ones are real paths; plus the pending ones: {name: why it is not usable yet}.

    Reads only (``digest``: a content hash of a file, e.g. the planner's cached one); ``pipe`` is not changed.
    """
    generated = {name: dataclasses.replace(gen, path=os.path.join(store.root, "generated", generated_key(gen)))
                 for name, gen in pipe.generated.items()}
    pending: dict[str, str] = {}
    for name in generated_names_used(pipe):
        folder = generated[name].path
        if not os.path.exists(folder):
            pending[name] = "not generated yet"
        else:
            problem = check_folder(folder, digest)
            if problem is not None:
                pending[name] = problem
    folders = {n: g.path for n, g in generated.items() if n not in pending}
    datasets = {n: dataclasses.replace(ds, path=_substitute(ds.path, folders)) for n, ds in pipe.datasets.items()}
    stages = {n: dataclasses.replace(st, params=_substitute(st.params, folders)) for n, st in pipe.stages.items()}
    resolved = dataclasses.replace(pipe, params=_substitute(pipe.params, folders), generated=generated,
                                   datasets=datasets, stages=stages)
    return resolved, pending


def write_generated(pipe: Pipeline, store: Store, names: list[str], log) -> None:
    """Run the generators of the datasets ``names`` (of a resolved pipeline) into their folders.

    Each is written into a private temporary folder, sealed and renamed into place, so a killed run leaves
    no half dataset; a folder that exists but fails its seal is moved aside first (with a warning)."""
    for name in names:
        gen = pipe.generated[name]
        if os.path.exists(gen.path):
            problem = check_folder(gen.path)
            if problem is None:
                continue  # written meanwhile by another run
            warn_once(f"generated dataset '{name}' ({gen.path}): {problem}; generating it again")
            store.discard(gen.path)
        log(f"generating dataset '{name}' with {gen.generator} {gen.params} -> {gen.path}")
        tmp = store.tmp_dir()
        func = registry.get(gen.generator).func
        with one_blas_thread():   # the same files on any machine, whatever its cores (stages/blas.py)
            if audit.enabled():
                audit.audited(lambda: func(out_dir=tmp, **gen.params), f"generator {gen.generator}", func)
            else:
                func(out_dir=tmp, **gen.params)
        seal_folder(tmp, {"generator": gen.generator, "params": gen.params})
        os.makedirs(os.path.dirname(gen.path), exist_ok=True)
        try:
            os.rename(tmp, gen.path)
        except OSError:
            if check_folder(gen.path) is not None:
                raise
            shutil.rmtree(tmp, ignore_errors=True)
