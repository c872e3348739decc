"""The metrics of a configuration, read from the cache (``results``); runs nothing."""
from __future__ import annotations

from typing import Any

from .plan import Plan
from .store import left_out_of


def metrics(plan: Plan) -> dict:
    """The merged values of the stages marked ``metrics: true``.

    A dict-valued result contributes its keys, any other value appears under the stage name. Stages not
    computed yet are listed under ``"_not_computed"``, stages skipped (an optional input is absent) under
    ``"_skipped"`` ({stage: why}); the items a metrics stage was computed without (they failed upstream) under
    ``"_left_out"`` ({stage: [{"item": "views[s003]", "why": "ValueError: ..."}]}). A dict result's
    ``"warnings"`` (a list of sentences: what a user should look at, e.g. a result the stage is unsure of) is
    gathered under ``"_warnings"`` ({stage: [str]}) instead, so two stages' warnings never overwrite each other;
    ``results`` prints them and the report shows them on its first screen.
    """
    merged: dict[str, Any] = {}
    missing = []
    for name, sp in plan.stages.items():
        if not sp.spec.metrics:
            continue
        if sp.pending is not None or sp.waiting is not None:  # no tasks yet: generated data or candidates to come
            missing.append(name)
        if sp.skipped is not None:
            merged.setdefault("_skipped", {})[name] = sp.skipped
        for t in sp.tasks:
            manifest = plan.store.complete(t.key)
            if manifest is None:
                missing.append(name)
                continue
            value = plan.store.get(t.key)
            left_out = left_out_of(manifest)
            if left_out:  # computed without some failed items: say which, and why
                merged.setdefault("_left_out", {})[name] = [{"item": failed, "why": why}
                                                            for _, failed, _, why in left_out]
            if isinstance(value, dict):
                value = dict(value)
                warnings = value.pop("warnings", None)
                if warnings:
                    merged.setdefault("_warnings", {}).setdefault(name, []).extend(str(w) for w in warnings)
                merged.update(value)
            else:
                merged[name] = value
    if missing:
        merged["_not_computed"] = sorted(set(missing))
    return merged


def scalar_metrics(m: dict, prefix: str = "") -> dict[str, Any]:
    """Flatten nested metric dicts (of at most 12 entries) to dotted keys, keeping numbers and short strings."""
    out = {}
    for k, v in m.items():
        if k.startswith("_"):
            continue
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            if len(v) <= 12:
                out.update(scalar_metrics(v, name + "."))
        elif isinstance(v, bool) or isinstance(v, (int, float)):
            out[name] = v
        elif isinstance(v, str) and len(v) < 20:
            out[name] = v
    return out


def format_results(pairs: list[tuple[str, Any]], n_headline: int | None = None) -> str:
    """One ``key value`` line per metric (floats to 4 significant digits); a key holding a space is quoted
    (JSON string), so each line stays two fields; a blank line after the first ``n_headline`` lines."""
    import json

    lines = []
    for i, (k, v) in enumerate(pairs):
        if n_headline and i == n_headline:
            lines.append("")
        key = json.dumps(k, ensure_ascii=False) if any(c.isspace() for c in k) else k
        lines.append(f"{key:<40} {v:.4g}" if isinstance(v, float) else f"{key:<40} {v}")
    return "\n".join(lines)


def _override(key: str, value: Any) -> str:
    """A ``--set`` text for one parameter value (JSON is valid YAML, so lists, numbers and booleans round-trip)."""
    import json

    return f"{key}={value}" if isinstance(value, str) else f"{key}={json.dumps(value)}"


def result(pipeline: str | Plan, stage: str, item: str | None = None, params: dict | None = None,
           cache_dir: str | None = None) -> Any:
    """The stored result of one task of ``stage``: its value as the stage function returned it (dicts, arrays,
    numbers), read from the cache; runs nothing.

    pipeline: a pipeline file (planned with ``params``: {key: value} like ``--set key=value``, and
    ``cache_dir``), or a ``Plan``. item: the item name of a per-item stage (e.g. "mesh004"), the tile label of
    a pairs stage, None for a once stage. Raises ``UserError`` naming the stage / item and what to do when the
    stage or item is unknown or the task is not computed yet (with these params).

        from stages import api
        r = api.result("pipelines/scape.yaml", "dense_auto", "mesh004", params={"dense_auto.n_patches": 300})
        r["vertex_map"]          # (n_template,) int: target vertex of each template vertex
    """
    from .errors import UserError
    from .plan import plan_pipeline

    plan = pipeline if isinstance(pipeline, Plan) else plan_pipeline(
        pipeline, [_override(k, v) for k, v in (params or {}).items()], cache_dir=cache_dir)
    if stage not in plan.stages:
        raise UserError(f"no stage '{stage}' in the pipeline", fix=f"use one of: {', '.join(plan.stages)}")
    sp = plan.stages[stage]
    if sp.skipped is not None:
        raise UserError(f"stage '{stage}' is skipped: {sp.skipped}", fix="give the input it needs")
    labels = {t.label: t for t in sp.tasks}
    if item is None and len(sp.tasks) == 1:
        task = sp.tasks[0]
    elif item in labels:
        task = labels[item]
    else:
        shown = ", ".join(list(labels)[:10]) + (" ..." if len(labels) > 10 else "")
        what = "is a per-item stage: name the item" if item is None else f"has no item '{item}'"
        raise UserError(f"stage '{stage}' {what}" + (f" (its items: {shown})" if labels else " (no tasks planned "
                        "yet: its input is generated or waited for by the run)"),
                        fix="pass item= one of its items" if labels else "run the pipeline first")
    if not plan.store.has(task.key):
        where = f"{stage}[{item}]" if item is not None else stage
        raise UserError(f"{where} is not computed with these params (cache {getattr(plan.store, 'root', '?')})",
                        fix="run the pipeline with the same --set values first (python -m stages run ...)")
    return plan.store.get(task.key)
