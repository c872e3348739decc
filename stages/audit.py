"""Code audit by observation: the project functions a call actually executes, against its code fingerprint.

A code fingerprint (``stages.fingerprint``) is built by reading source: whatever it fails to follow is code a
task can run without it being in the task's cache key, i.e. an edit there would be served a stale result. The
audit closes that loop by watching instead of reading: with ``STAGES_AUDIT_CODE=1`` in the environment, every
task (and every generator) runs under ``sys.setprofile``; each project function that executes must be covered
by a part of the fingerprint (itself, an enclosing function or class, or its whole module), otherwise the task
fails naming the functions the fingerprint missed. It is slower (every call is seen), so it is meant for tests
and for checking a new plugin: ``STAGES_AUDIT_CODE=1 python -m stages run pipeline.yaml --cache /tmp/audit``.
"""
from __future__ import annotations

import os
import sys
import threading
from typing import Any, Callable

from . import registry
from .fingerprint import code_fingerprint

ENV = "STAGES_AUDIT_CODE"


class CodeAuditError(RuntimeError):
    """Project functions ran that the code fingerprint does not cover."""


def enabled() -> bool:
    """True when the environment asks for the audit (``STAGES_AUDIT_CODE`` set to anything but ''/0)."""
    return os.environ.get(ENV, "") not in ("", "0")


class CallRecorder:
    """Context manager recording the (module, qualified name) of every Python function called inside it, in
    this thread and in threads started meanwhile (until it exits: a thread started inside that outlives it, e.g.
    one a cluster starting alongside spawned, stops being watched at its next call)."""

    def __init__(self):
        self._modules: dict[Any, str | None] = {}
        self._recording = False

    def _profile(self, frame, event, arg):
        if not self._recording:
            sys.setprofile(None)    # a thread started while recording, still running after it
            return
        if event == "call":
            code = frame.f_code
            if code not in self._modules:
                self._modules[code] = frame.f_globals.get("__name__")

    def __enter__(self) -> "CallRecorder":
        self._previous = sys.getprofile()
        self._recording = True
        sys.setprofile(self._profile)
        threading.setprofile(self._profile)
        return self

    def __exit__(self, *exc) -> None:
        self._recording = False
        sys.setprofile(self._previous)
        threading.setprofile(None)

    def executed(self) -> set[tuple[str, str]]:
        """{(module name, qualified name)} of the functions that ran from source files (generated code such
        as a dataclass's ``__init__``, and module bodies run by an import, are left out)."""
        modules = self._modules.copy()      # one step under the GIL: a late thread cannot resize it meanwhile
        return {(mod, code.co_qualname) for code, mod in modules.items()
                if mod and not code.co_filename.startswith("<") and code.co_qualname != "<module>"}


def _in_project(module: str, project: frozenset) -> bool:
    parts = module.split(".")
    return any(".".join(parts[:i]) in project for i in range(1, len(parts) + 1))


def uncovered(executed: set[tuple[str, str]], parts: dict[str, str], project: frozenset) -> list[str]:
    """The executed project functions (``module.qualname``) that no fingerprint part covers, sorted.

    A part covers a function when it is the function itself, an enclosing function or class (a method, a
    nested function, a comprehension) or its whole module (``module:NAME``)."""
    missing = []
    for module, qualname in executed:
        if not _in_project(module, project) or f"module:{module}" in parts:
            continue
        names = qualname.split(".")
        if not any(f"{module}.{'.'.join(names[:i])}" in parts for i in range(1, len(names) + 1)):
            missing.append(f"{module}.{qualname}")
    return sorted(missing)


def function_parts(func: Callable, *more: Callable | None) -> tuple[frozenset, dict[str, str]]:
    """(project, parts): the packages the fingerprints follow plus the functions' modules, and the merged
    fingerprint parts of ``func`` and of the other functions given (e.g. a stage's mirror)."""
    packages = registry.fingerprint_packages()
    project, parts = frozenset(packages), {}
    for f in (func,) + more:
        if f is not None:
            project |= {f.__module__}
            parts.update(code_fingerprint(f, packages)[1])
    return project, parts


def audited(call: Callable[[], Any], what: str, func: Callable, *more: Callable | None) -> Any:
    """``call()`` under a :class:`CallRecorder`; CodeAuditError naming ``what`` and the project functions that
    ran outside the fingerprint of ``func`` (and ``more``), else the call's value."""
    with CallRecorder() as recorder:
        value = call()
    project, parts = function_parts(func, *more)
    missing = uncovered(recorder.executed(), parts, project)
    if missing:
        raise CodeAuditError(f"code audit of {what}: {len(missing)} project function(s) ran that its code "
                             f"fingerprint does not cover: {', '.join(missing)}")
    return value
