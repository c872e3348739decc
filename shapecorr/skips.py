"""A per-mesh result that was skipped, and why: the one marker the dense stages store, pass on and check.

The engine skips whole stages (an optional input absent: ``SourceKind.SKIPPED``); a single item of a stage that
runs, such as a target mesh without the landmarks ``dense_sparse`` needs, is skipped by the stage function
itself. Its result is then ``skipped(why)``, a plain dict so that the engine's codec stores it like any result;
code reads it only through ``is_skipped`` / ``skip_reason`` / ``skip_reasons``.
"""
from __future__ import annotations

_KEY = "skipped"


def skipped(why: str) -> dict:
    """The result of an item skipped because of ``why`` (a sentence naming the mesh and what it lacks)."""
    return {_KEY: str(why)}


def is_skipped(result) -> bool:
    """Whether ``result`` (a stage function's result for one item) is ``skipped(...)``."""
    return isinstance(result, dict) and _KEY in result


def skip_reason(result) -> str | None:
    """Why ``result`` was skipped, or None when it was not."""
    return result[_KEY] if is_skipped(result) else None


def skip_reasons(results: dict | None) -> dict[str, str]:
    """{item: why} of the skipped ones among ``results`` ({item: result}, or None), sorted by item."""
    return {m: skip_reason(r) for m, r in sorted((results or {}).items()) if is_skipped(r)}
