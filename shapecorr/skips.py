"""A per-mesh result that was skipped, and why: the engine's ``stages.skipped.Skipped``, made and read here.

A single item of a stage that runs, such as a target mesh without the landmarks ``dense_sparse`` needs, is skipped
by the stage function itself: its result is ``skipped(why)``, which the engine stores and reports (``run`` prints
each one). The stages that receive such results read them only through ``is_skipped`` / ``skip_reason`` /
``skip_reasons`` / ``without_skipped`` / ``holds``.
"""
from __future__ import annotations

from stages.skipped import Skipped


def skipped(why: str) -> Skipped:
    """The result of an item skipped because of ``why`` (a sentence naming the mesh and what it lacks)."""
    return Skipped(str(why))


def is_skipped(result) -> bool:
    """Whether ``result`` (a stage function's result for one item) is ``skipped(...)``."""
    return isinstance(result, Skipped)


def skip_reason(result) -> str | None:
    """Why ``result`` was skipped, or None when it was not."""
    return result.why if is_skipped(result) else None


def skip_reasons(results: dict | None) -> dict[str, str]:
    """{item: why} of the skipped ones among ``results`` ({item: result}, or None), sorted by item."""
    return {m: skip_reason(r) for m, r in sorted((results or {}).items()) if is_skipped(r)}


def without_skipped(results: dict | None) -> dict:
    """``results`` ({item: result}, or None) without the skipped ones (an empty dict for None)."""
    return {m: r for m, r in (results or {}).items() if not is_skipped(r)}


def holds(result, key: str) -> bool:
    """Whether ``result`` (one item's result, or None when the input is absent) is a computed result with ``key``."""
    return result is not None and not is_skipped(result) and key in result
