"""The engine's Python API in one place (what the CLI calls)::

    from stages import api
    summary = api.run("pipeline.yaml", overrides=["mrf.sigma=0.5"], workers=2)
    api.metrics(api.plan_pipeline("pipeline.yaml"))
    api.result("pipeline.yaml", "dense_auto", "mesh001")    # one stage's stored result for one item
"""
from __future__ import annotations

from .gc import gc
from .plan import Plan, build_plan, plan_pipeline
from .publish import publish
from .report import write_report
from .results import metrics, result, scalar_metrics
from .run import RunFailed, run
from .session import client_session
from .status import dry_run, format_dry_run, status
from .sweep import format_table, parse_grid, sweep, write_table

__all__ = ["Plan", "RunFailed", "build_plan", "client_session", "dry_run", "format_dry_run", "format_table", "gc",
           "metrics", "parse_grid", "plan_pipeline", "publish", "result", "run", "scalar_metrics", "status", "sweep", "write_table",
           "write_report"]
