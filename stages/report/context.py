"""What the report shows, gathered once from the plan, the store, the run record, sweeps and output folder."""
from __future__ import annotations

import glob
import os
import time
from dataclasses import dataclass, field
from typing import Iterable

from ..headline import HeadlineTable, headline_tables
from ..plan import Plan, plan_pipeline
from ..record import load_record, sweep_record_files
from ..results import metrics as pipeline_metrics
from ..checksums import read_checked_json
from .markup import IMAGE_TYPES
from .versions import git_commit, package_versions


@dataclass
class ReportContext:
    """Everything one report page is built from (read-only: building it runs and writes nothing)."""
    plan: Plan
    record: dict | None                  # the last run record of this pipeline file (None: never run)
    overrides: list[str]                 # the configuration shown (``--set`` strings)
    pipeline_arg: str                    # the pipeline path as the user gave it (for commands shown)
    out_path: str                        # the HTML file written
    now: float                           # UNIX time the report is written
    stored: int                          # tasks of this configuration whose result is in the cache
    total: int                           # tasks of this configuration
    record_differs: bool                 # the last run used another configuration
    metrics: dict                        # merged metrics (see stages.results.metrics)
    metric_origin: dict[str, str]        # top-level metric key -> stage that produced it
    sweeps: list[dict]                   # recorded sweeps of this pipeline file, oldest first
    images: list[str]                    # published PNG/SVG files, relative to the output folder
    caption_files: set[str]              # <figure>.txt files that caption an image
    figures_by_group: dict[str, list[str]]  # top-level folder ("" for the folder itself) -> images
    other_files: list[str]               # published files that are neither images nor captions
    stage_seconds: dict[str, float | None]  # summed compute seconds of each stage's stored results
    versions: dict[str, str]             # package -> version
    git: str | None                      # commit of the engine's checkout, if in a git repository
    files: list[str] = field(default_factory=list)  # every published file, relative
    headlines: list[HeadlineTable] = field(default_factory=list)  # the plugins' summary tables, filled

    @property
    def summary_figures(self) -> list[str]:
        """The images the summary shows (next to the headline tables), each once."""
        return list(dict.fromkeys(f for t in self.headlines for f in t.figures))

    def sweep_figure(self, sw: dict) -> str | None:
        """The published plot of a recorded sweep (relative to the output folder), if there is one."""
        name = sw.get("figure_file") or os.path.basename(sw.get("_file", ""))[:-5] + ".png"   # older records
        rel = "sweeps/" + name
        return rel if rel in self.images else None

    @property
    def placed(self) -> dict[str, str]:
        """Image -> the section that embeds it instead of its stage's figure section (each image is embedded
        once): the headline figures in the summary, sweep plots in the sweeps section."""
        out = {rel: "sweeps" for rel in (self.sweep_figure(sw) for sw in self.sweeps) if rel}
        out.update({rel: "summary" for rel in self.summary_figures})
        return out

    @property
    def nothing_run(self) -> bool:
        return self.stored == 0

    @property
    def incomplete(self) -> bool:
        return 0 < self.stored < self.total

    @property
    def output_dir(self) -> str:
        return self.plan.pipeline.output_dir


def published_files(output_dir: str, exclude: Iterable[str] = ()) -> list[str]:
    """Relative paths (with '/') of every file under ``output_dir``, sorted; ``exclude``: absolute paths."""
    skip = {os.path.abspath(p) for p in exclude}
    out = []
    for dirpath, dirnames, files in os.walk(output_dir):
        dirnames.sort()
        for f in files:
            full = os.path.abspath(os.path.join(dirpath, f))
            if full not in skip and not f.endswith(".tmp"):
                out.append(os.path.relpath(full, output_dir).replace(os.sep, "/"))
    return sorted(out)


def caption_file(rel: str) -> str:
    """The caption file of an image: ``a/b.png`` -> ``a/b.txt``."""
    return os.path.splitext(rel)[0] + ".txt"


def stage_seconds(plan: Plan) -> dict[str, float | None]:
    """Per stage: the summed compute seconds of its stored tasks (from the manifests), None if none stored."""
    out: dict[str, float | None] = {}
    for name, sp in plan.stages.items():
        secs = [(plan.store.manifest(t.key) or {}).get("info", {}).get("seconds") for t in sp.tasks
                if plan.store.has(t.key)]
        secs = [s for s in secs if isinstance(s, (int, float))]
        out[name] = round(sum(secs), 4) if secs else None
    return out


def metric_origins(plan: Plan) -> dict[str, str]:
    """Top-level metric key -> the metrics stage whose result holds it (read from the manifests)."""
    origin = {}
    for name, sp in plan.stages.items():
        if not sp.spec.metrics:
            continue
        for t in sp.tasks:
            tree = (plan.store.manifest(t.key) or {}).get("tree")
            if isinstance(tree, dict) and "__dict__" in tree:
                for k in tree["__dict__"]:
                    origin[k] = name
            elif tree is not None:
                origin[name] = name
    return origin


def load_sweeps(plan: Plan) -> list[dict]:
    """The recorded sweeps of this pipeline file, oldest first (each with its file name under "_file")."""
    out = []
    for path in sweep_record_files(plan):
        sw = read_checked_json(path, "the report leaves this sweep out")
        if sw is None:
            continue
        sw["_file"] = path
        out.append(sw)
    return sorted(out, key=lambda s: s.get("time", 0))


def _record_differs(plan: Plan, record: dict | None) -> bool:
    if not record:
        return False
    keys = {(n, lbl): v.get("key") for n, s in record.get("stages", {}).items()
            for lbl, v in s.get("tasks", {}).items()}
    return any(keys.get((t.stage, t.label)) != t.key for t in plan.tasks())


def build_context(pipeline_path: str, overrides=(), cache_dir=None, out=None, output_dir=None) -> ReportContext:
    """Gather the report of one configuration of ``pipeline_path`` (runs no stage, writes nothing);
    ``output_dir``: the published output folder (default: the pipeline's)."""
    overrides = list(overrides or ())
    plan = plan_pipeline(pipeline_path, overrides, cache_dir, output_dir, quiet=True)
    out_path = os.path.abspath(out or os.path.join(plan.pipeline.output_dir, "report.html"))
    tasks = plan.tasks()
    out_dir = plan.pipeline.output_dir
    earlier_reports = glob.glob(os.path.join(glob.escape(out_dir), "*.html"))
    files = published_files(out_dir, exclude=[out_path, *earlier_reports]) if os.path.isdir(out_dir) else []
    images = [f for f in files if os.path.splitext(f)[1].lower() in IMAGE_TYPES]
    captions = {caption_file(f) for f in images} & set(files)
    figures_by_group: dict[str, list[str]] = {}
    for rel in images:
        figures_by_group.setdefault(rel.split("/", 1)[0] if "/" in rel else "", []).append(rel)
    record = load_record(plan)
    seconds = stage_seconds(plan)
    merged = pipeline_metrics(plan)
    return ReportContext(
        plan=plan, record=record, overrides=overrides, pipeline_arg=pipeline_path, out_path=out_path,
        now=time.time(), stored=sum(plan.store.has(t.key) for t in tasks), total=len(tasks),
        record_differs=_record_differs(plan, record), metrics=merged,
        metric_origin=metric_origins(plan), sweeps=load_sweeps(plan), images=images, caption_files=captions,
        figures_by_group=figures_by_group, other_files=[f for f in files if f not in images and f not in captions],
        stage_seconds=seconds, versions=package_versions(plan),
        git=git_commit(os.path.dirname(os.path.abspath(__file__))), files=files,
        headlines=headline_tables(plan, merged, seconds, images))

