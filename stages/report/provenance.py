"""Provenance of a report: per-stage counts and code fingerprints, parameters, the pipeline file, package
versions (the engine's and those the application's plugins declare) and the git commit."""
from __future__ import annotations

import hashlib
import os
import platform
import sys

from .context import ReportContext
from .markup import esc, folded, json_pre, table, when


def _stage_rows(ctx: ReportContext) -> list[list]:
    plan, record = ctx.plan, ctx.record
    last = (record or {}).get("summary", {}).get("stages", {})
    rec_stages = (record or {}).get("stages", {})
    rows = []
    for name, sp in plan.stages.items():
        s = last.get(name, {})
        stored = sum(plan.store.has(t.key) for t in sp.tasks)
        seconds = ctx.stage_seconds.get(name)
        rows.append([name, sp.spec.function, sp.spec.fanout, len(sp.tasks), stored,
                     s.get("executed", "-"), s.get("cached", "-"), s.get("failed", "-"), s.get("skipped", "-"),
                     s.get("seconds", "-"), seconds if seconds is not None else "-", sp.code[:12],
                     "" if rec_stages.get(name, {}).get("code") in (None, sp.code) else "changed since last run"])
    return rows


def _pipeline_file_block(path: str) -> str:
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except OSError:
        return ""
    digest = hashlib.blake2b(text.encode(), digest_size=16).hexdigest()
    return folded(f"pipeline file {os.path.basename(path)} (blake2b {digest})", f"<pre>{esc(text)}</pre>")


def provenance_section(ctx: ReportContext) -> str:
    """Stages (counts of the last run, fingerprints), parameters and code parts, the pipeline file, environment."""
    plan, record = ctx.plan, ctx.record
    parts = ["<h3>Stages</h3>"]
    if not record:
        parts.append('<p class="muted">No run recorded yet: executed / cached counts are unknown.</p>')
    parts.append(table(["stage", "function", "fanout", "tasks", "in cache now", "executed (last run)",
                        "cached (last run)", "failed", "skipped", "seconds (last run)",
                        "compute seconds (stored results)", "code fingerprint", "code"], _stage_rows(ctx),
                       cls="provenance"))
    if record:
        summ = record.get("summary") or {}
        note = f"; the last run was a no-op taking {summ['last_noop']} s" if "last_noop" in summ else ""
        parts.append(f"<p>Last run: {esc(when(record.get('time')))}, wall time {esc(summ.get('wall_seconds', '?'))} s"
                     f"{esc(note)}; overrides <code>{esc(' '.join(record.get('overrides') or []) or '(none)')}</code>."
                     "</p>")
    parts.append("<h3>Stage parameters and code</h3>")
    for name, sp in plan.stages.items():
        code_rows = [[fn, digest[:16]] for fn, digest in sorted(sp.code_parts.items())]
        inner = ("<p>Parameters:</p>" + json_pre(sp.spec.params)
                 + f"<p>Code fingerprint <code>{esc(sp.code)}</code>, from:</p>"
                 + table(["project function / constant", "fingerprint"], code_rows))
        parts.append(folded(f"{name}: {sp.spec.function}", inner))
    parts.append("<h3>Pipeline parameters</h3>" + json_pre(plan.pipeline.params))
    parts.append(_pipeline_file_block(plan.pipeline.file))
    parts.append("<h3>Environment</h3>")
    env_rows = [[k, v] for k, v in ctx.versions.items()]
    env_rows += [["platform", platform.platform()], ["executable", sys.executable]]
    if ctx.git:
        env_rows.append(["git commit", ctx.git])
    parts.append(table(["package", "version"], env_rows, cls="versions"))
    return "".join(parts)
