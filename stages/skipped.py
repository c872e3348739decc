"""``Skipped``: the result of one item a stage function chose not to compute, and why (stored, reported by run).

The engine skips whole tasks whose inputs failed (``TaskStatus.SKIPPED``) and whole stages whose optional input is
absent (``SourceKind.SKIPPED``). An item the function itself cannot compute, though nothing failed (say a target
mesh without the landmarks its method needs), is returned as ``Skipped("mesh003 has no landmark file")``: the
store keeps it like any result (a rerun does not try again until something changes), ``run`` prints each one
and counts them per stage ("items_skipped" in its summary), and the stages that receive it see a ``Skipped``.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Skipped:
    """An item a stage function did not compute: ``why`` names the item and what it lacks (one sentence)."""
    why: str

    def __post_init__(self):
        if not isinstance(self.why, str) or not self.why.strip():
            raise ValueError(f"Skipped needs a reason (a non-empty sentence), got {self.why!r}")
