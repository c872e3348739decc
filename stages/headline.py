"""Headline tables: the methods x measures tables the plugins declare, filled from a configuration's metrics.

The plugins declare them as :class:`stages.registry.Headline`; shared by the report's summary, ``sweep``'s printed
table and the order in which ``results`` lists the metrics.

Generic: everything application-specific (rows, measures, which is better, the figures that carry the result)
comes from the plugin declarations; this module only resolves metric keys and marks the best value.
"""
from __future__ import annotations

import fnmatch
import math
from dataclasses import dataclass, field
from typing import Any

from . import registry
from .plan import Plan
from .results import scalar_metrics

SECONDS_PER_TASK = "@seconds_per_task"


@dataclass
class HeadlineTable:
    """One filled headline table: ``cells[r][c]`` is the value of measure c for row r (None: not available)."""
    group: str
    title: str
    rows: list[str]
    columns: list[str]
    better: list[str | None]
    cells: list[list[float | None]]
    keys: list[list[str | None]]          # the metric key behind each cell (None: none / derived)
    figures: list[str] = field(default_factory=list)   # published images (relative to the output folder)

    def best_rows(self, col: int) -> set[int]:
        """Rows holding the best value of column ``col`` (empty when the column has no direction or values)."""
        return best_indices([r[col] for r in self.cells], self.better[col])


def is_number(v: Any) -> bool:
    """True for finite ints and floats (not bools)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(float(v))


def best_indices(values: list[Any], better: str | None) -> set[int]:
    """Indices of the best numeric values (``better`` "max" or "min"; ties all count); empty when the
    direction is None, fewer than two rows have a value or all values are equal (nothing to compare)."""
    nums = [(i, float(v)) for i, v in enumerate(values) if is_number(v)]
    if better not in ("max", "min") or len({v for _, v in nums}) < 2:
        return set()
    target = max(v for _, v in nums) if better == "max" else min(v for _, v in nums)
    return {i for i, v in nums if v == target}


def _feeding_stage(plan: Plan, input_name: str) -> str | None:
    """The stage wired to ``input_name`` of a metrics stage (the first such stage of the plan)."""
    for sp in plan.stages.values():
        ref = sp.spec.inputs.get(input_name) if sp.spec.metrics else None
        if ref is not None and getattr(ref, "source", None) in plan.stages:
            return ref.source
    return None


def _seconds_per_task(plan: Plan, stage_seconds: dict, row: str, headline: registry.Headline) -> float | None:
    stage = _feeding_stage(plan, headline.row_inputs.get(row, row))
    secs = stage_seconds.get(stage) if stage else None
    n = len(plan.stages[stage].tasks) if stage else 0
    return round(secs / n, 4) if secs is not None and n else None


def _cell(flat: dict, measure: registry.Measure, row: str) -> tuple[Any, str | None]:
    if measure.only_row and str(flat.get(measure.only_row)) != row:
        return None, None
    key = measure.per_row.get(row, measure.key).replace("{row}", row)
    value = flat.get(key)
    if not is_number(value):
        return None, None
    if measure.divide_by:
        denom = flat.get(measure.divide_by)
        return (float(value) / float(denom), None) if is_number(denom) and denom else (None, None)
    return value, key


def _rows(headline: registry.Headline, metrics: dict) -> list[str]:
    if headline.rows:
        return list(headline.rows)
    source = metrics
    for part in (headline.rows_from or "").split("."):
        source = source.get(part, {}) if isinstance(source, dict) else {}
    return [str(k) for k in source] if isinstance(source, dict) else []


def headline_figures(plan: Plan, images: list[str], specs: tuple[str, ...]) -> list[str]:
    """The published images named by ``"function:file"`` specs (for every stage running that function)."""
    out = []
    for spec in specs:
        function, _, name = spec.partition(":")
        for stage, sp in plan.stages.items():
            rel = f"{stage}/{name}"
            if sp.spec.function == function and rel in images and rel not in out:
                out.append(rel)
    return out


def fill_headline(plan: Plan, headline: registry.Headline, metrics: dict, stage_seconds: dict | None = None,
                  images: list[str] = ()) -> HeadlineTable | None:
    """The table of one declared headline for these metrics; None when no cell has a value."""
    flat = scalar_metrics(metrics)
    rows, cells, keys = [], [], []
    for row in _rows(headline, metrics):
        values, row_keys = [], []
        for m in headline.measures:
            if m.key == SECONDS_PER_TASK:
                v, k = _seconds_per_task(plan, stage_seconds or {}, row, headline), None
            else:
                v, k = _cell(flat, m, row)
            values.append(v)
            row_keys.append(k)
        if any(v is not None for v, m in zip(values, headline.measures) if m.key != SECONDS_PER_TASK):
            rows.append(row)
            cells.append(values)
            keys.append(row_keys)
    if not rows:
        return None
    return HeadlineTable(headline.group, headline.title, rows, [m.label for m in headline.measures],
                         [m.better for m in headline.measures], cells, keys,
                         headline_figures(plan, list(images), headline.figures))


def headline_tables(plan: Plan, metrics: dict, stage_seconds: dict | None = None,
                    images: list[str] = ()) -> list[HeadlineTable]:
    """The filled headline tables the plan's plugins declare, in declaration order (empty ones left out)."""
    functions = [sp.spec.function for sp in plan.stages.values()]
    tables = (fill_headline(plan, h, metrics, stage_seconds, images) for h in registry.headlines(functions))
    return [t for t in tables if t is not None]


def key_directions(plan: Plan, metrics: dict) -> dict[str, str | None]:
    """Metric key -> "max"/"min"/None for every metric key a headline cell reads (for marking sweep tables)."""
    out: dict[str, str | None] = {}
    for t in headline_tables(plan, metrics):
        for row_keys in t.keys:
            for k, better in zip(row_keys, t.better):
                if k:
                    out.setdefault(k, better)
    return out


def sweep_columns(plan: Plan, metrics: dict, requested: list[str] | None = None) -> list[str]:
    """The metric keys a sweep table shows: ``requested`` (dotted keys or glob patterns such as
    ``accuracy.*``), else the plugins' ``sweep_metrics``, else every headline cell; only keys with a scalar
    value in ``metrics`` (point 0's), in the order given."""
    flat = scalar_metrics(metrics)
    functions = [sp.spec.function for sp in plan.stages.values()]
    patterns = list(requested or registry.sweep_metrics(functions) or key_directions(plan, metrics))
    out = []
    for pat in patterns:
        out += [k for k in flat if fnmatch.fnmatchcase(k, pat) and k not in out]
    return out


def headline_first(plan: Plan, m: dict) -> tuple[list[tuple[str, Any]], int]:
    """``scalar_metrics(m)`` as (key, value) pairs: the keys the plugins' headline tables read first, in the
    tables' order (table by table, row by row, measure by measure: the report's summary), then the others in
    their stored order; and how many are headline keys."""
    flat = scalar_metrics(m)
    head = [k for k in key_directions(plan, m) if k in flat]
    return [(k, flat[k]) for k in head] + [(k, v) for k, v in flat.items() if k not in set(head)], len(head)
