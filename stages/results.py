"""The metrics of a configuration, read from the cache (``results``); runs nothing."""
from __future__ import annotations

from typing import Any

from .plan import Plan


def metrics(plan: Plan) -> dict:
    """The merged values of the stages marked ``metrics: true``.

    A dict-valued result contributes its keys, any other value appears under the stage name. Stages not
    computed yet are listed under ``"_not_computed"``, stages skipped (an optional input is absent) under
    ``"_skipped"`` ({stage: why}); the items a metrics stage was computed without (they failed upstream) under
    ``"_left_out"`` ({stage: [{"item": "views[s003]", "why": "ValueError: ..."}]}).
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
            if not plan.store.has(t.key):
                missing.append(name)
                continue
            value = plan.store.get(t.key)
            left_out = plan.store.left_out(t.key)
            if left_out:  # computed without some failed items: say which, and why
                merged.setdefault("_left_out", {})[name] = [{"item": failed, "why": why}
                                                            for _, failed, _, why in left_out]
            if isinstance(value, dict):
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
