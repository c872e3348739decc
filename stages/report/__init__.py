"""One self-contained HTML report of a pipeline: figures, metrics, sweeps and provenance.

``write_report("pipeline.yaml")`` reads only what the engine already stored (the cache, the last run record,
the recorded sweeps and the published output folder); it runs no stage and writes only the report file.
Images are embedded as base64 data URIs and the CSS is inline, so the file can be mailed or archived on its own.

The page opens on a summary: what ran on which data (and what came from the cache), then the headline tables
the plugins declare (:class:`stages.registry.Headline`: methods x measures, the best value starred) next to
the figures that carry the result. Everything else follows, folded: figures are grouped into sections by the
``group`` each stage function was registered with (titles from the plugins, see
:class:`stages.registry.Plugin`); each image is embedded once (elsewhere a pointer to it).

Modules: ``markup`` (HTML building blocks and value rendering), ``context`` (gathering), ``headline`` (the
summary tables, shared with ``sweep``), ``sections`` (summary, figures, metrics, sweeps), ``provenance``
(stages, code, versions, git).
"""
from __future__ import annotations

import os

from .. import registry
from ..checksums import atomic_write_text
from .context import ReportContext, build_context
from .markup import CSS, esc, folded, render_value, when
from .provenance import provenance_section
from .sections import figures_block, files_section, metrics_section, summary_section, sweeps_section

__all__ = ["ReportContext", "build_context", "render_html", "render_value", "write_report"]


def _stages_by_group(ctx: ReportContext) -> dict[str | None, list[str]]:
    """Declared report group -> the plan's stages whose function belongs to it (None: no group)."""
    out: dict[str | None, list[str]] = {}
    for name, sp in ctx.plan.stages.items():
        out.setdefault(registry.get(sp.spec.function).group, []).append(name)
    return out


def _figure_sections(ctx: ReportContext) -> list[tuple[str, str, str]]:
    """(id, title, HTML) of the figure sections: one per declared group, then everything else."""
    plan = ctx.plan
    by_group = _stages_by_group(ctx)
    other_groups = [""] + sorted(g for g in ctx.figures_by_group if g and g not in plan.stages)
    if not any(k is not None for k in by_group):
        body = figures_block(ctx, list(plan.stages), other_groups)
        body = (body or '<p class="muted">No figures (PNG/SVG) in the output folder.</p>') + files_section(ctx)
        return [("figures", "Figures", body)]
    sections = []
    titles = registry.group_titles()
    for key in sorted((k for k in by_group if k is not None), key=lambda k: (list(titles).index(k)
                                                                            if k in titles else len(titles), k)):
        body = figures_block(ctx, by_group[key]) or '<p class="muted">No figures published by these stages yet.</p>'
        stage_list = ", ".join(f"{n} ({plan.stages[n].spec.function})" for n in by_group[key])
        sections.append((key, titles.get(key, key), f"<p>Stages: {esc(stage_list)}.</p>{body}"))
    rest = figures_block(ctx, by_group.get(None, []), other_groups) + files_section(ctx)
    if rest:
        sections.append(("figures", "Other figures and files", rest))
    return sections


def render_html(ctx: ReportContext) -> str:
    """The report page for a context from :func:`build_context`."""
    plan = ctx.plan
    sections = [("summary", "Summary", summary_section(ctx))] + _figure_sections(ctx)
    sections += [("sweeps", "Sweeps", sweeps_section(ctx)), ("metrics", "Metrics (details)", metrics_section(ctx)),
                 ("provenance", "Provenance", folded("parameters, code fingerprints, package versions, time per stage, "
                                                     "tasks executed vs cached", provenance_section(ctx)))]
    toc = "".join(f'<li><a href="#{sid}">{esc(title)}</a></li>' for sid, title, _ in sections)
    body = "".join(f'<section id="{sid}"><h2>{esc(title)}</h2>{content}</section>' for sid, title, content in sections)
    title = f"Pipeline report: {plan.pipeline.name}"
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{esc(title)}</title><style>{CSS}</style></head><body>"
            f"<h1>{esc(title)} <span class=\"muted small\">written {esc(when(ctx.now))}</span></h1>"
            f"<nav><h2>Contents</h2><ul>{toc}</ul></nav>{body}</body></html>\n")


def write_report(pipeline_path: str, overrides=(), cache_dir: str | None = None, out: str | None = None,
                 output_dir: str | None = None) -> str:
    """Write the self-contained HTML report of a pipeline configuration; returns the file written.

    Args:
        pipeline_path: the pipeline YAML.
        overrides: ``key=value`` strings as for ``run --set`` (the configuration whose metrics are shown).
        cache_dir: the cache folder (default: the pipeline's ``cache:``).
        out: the HTML file (default: ``<output folder>/report.html``).
        output_dir: the output folder whose published files are shown (default: the pipeline's ``output:``;
            give what ``run --out`` was given).
    """
    ctx = build_context(pipeline_path, overrides, cache_dir, out, output_dir)
    html = render_html(ctx)
    if out is None:  # in the output folder: a file of the engine's own, never one of the user's replaced
        from ..errors import UserError
        from ..publish import check_output_folder, write_output_file

        root = os.path.dirname(ctx.out_path)
        check_output_folder(root, ctx.plan.store.root)
        if write_output_file(root, os.path.basename(ctx.out_path), lambda tmp: atomic_write_text(tmp, html),
                             where=None) is None:
            raise UserError(f"{ctx.out_path} exists and was not written by the engine: not replaced",
                            fix="write the report elsewhere with --out FILE, or move that file away")
        return ctx.out_path
    atomic_write_text(ctx.out_path, html)
    return ctx.out_path
