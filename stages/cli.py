"""Command-line interface: run, status, sweep, results, gc, report, functions."""
from __future__ import annotations

import argparse
import json
import os
import sys

from .errors import PipelineError, UserError
from .logs import configure_logging

MAX_WORKERS = 4 * (os.cpu_count() or 1)

EPILOG = """examples (each is run by tests/stages/test_help_examples.py):
  python -m stages run pipeline.yaml
  python -m stages run pipeline.yaml --set mrf.sigma=0.5 --dry-run     # what would rerun, and why
  python -m stages run pipeline.yaml mrf                               # only mrf and what it needs
  python -m stages run pipeline.yaml --force dense_sparse              # recompute it and its downstream stages
  python -m stages sweep pipeline.yaml --grid align.sigma_scale=0.5,1,2
  python -m stages results pipeline.yaml --json
"""


def _workers(text: str) -> int:
    """--workers: an int in 0..MAX_WORKERS (more processes than that only compete for the cores)."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if not 0 <= n <= MAX_WORKERS:
        raise argparse.ArgumentTypeError(
            f"{n} is out of range: use 0 (run in this process) to {MAX_WORKERS} (4 per CPU core); "
            "for more, start a dask cluster and pass --scheduler")
    return n


def _output_file(example: str):
    """An argparse type for a file to write (--summary-json, report --out): not an existing folder."""
    def check(text: str) -> str:
        from .cache_root import expand_path
        try:
            text = expand_path(text)  # ~ and $VAR, as a shell would
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        if os.path.isdir(text) or text.endswith(("/", os.sep)):
            raise argparse.ArgumentTypeError(f"'{text}' is a folder; give a file name, e.g. "
                                             f"{os.path.join(text, example)}")
        return text
    return check


def _selection(p: argparse.ArgumentParser, what: str = "run") -> None:
    """Target stages (after the pipeline, or ``--until``) and ``--force``: the same in ``run`` and ``sweep``."""
    p.add_argument("targets", nargs="*", metavar="STAGE",
                   help=f"{what} only these stages and the stages they need (default: every stage)")
    p.add_argument("--until", action="append", default=[], metavar="STAGE",
                   help="the same as naming STAGE after the pipeline: STAGE and what it needs, nothing downstream")
    p.add_argument("--force", action="append", default=[], metavar="STAGE",
                   help="recompute STAGE and its downstream stages even when cached (e.g. after a library "
                        "upgrade); the stored results are replaced")


def _common(p: argparse.ArgumentParser, sets: bool = True) -> None:
    p.add_argument("pipeline", help="the pipeline YAML file")
    if sets:
        p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                       help="override a parameter: a.b=v sets params.a.b; STAGE.PARAM=v sets a stage's param")
    p.add_argument("--cache", default=None, metavar="DIR|URL",
                   help="cache folder, or an object store URL such as s3://BUCKET/PREFIX (needs the s3 extra; "
                        "endpoint and keys from AWS_* variables) (default: the pipeline's 'cache:' or ./cache)")


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    prog = "stages" if os.path.basename(sys.argv[0] or "") == "stages" else "python -m stages"  # console script
    parser = argparse.ArgumentParser(prog=prog, description=(
        "Declarative, cached, parallel pipelines for shape alignment and correspondence."),
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"stages {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("run", help="run a pipeline (only what changed is recomputed)",
                       description="Run a pipeline: compute the cache misses under dask, publish outputs. Before "
                                   "executing, one line per stage says how many tasks run and why.")
    _common(p)
    _selection(p)
    p.add_argument("--dry-run", action="store_true", help="list what would execute and why; run nothing")
    p.add_argument("--workers", type=_workers, default=2,
                   help=f"local worker processes, 0..{MAX_WORKERS} (default 2); 0 runs in this process without dask")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a dask.distributed scheduler address, e.g. tcp://10.0.0.5:8786")
    p.add_argument("--out", default=None, help="output folder (default: the pipeline's 'output:')")
    p.add_argument("--summary-json", default=None, metavar="PATH", type=_output_file("summary.json"),
                   help="write per-stage tasks executed / cached / seconds as JSON")
    p.add_argument("--quiet", action="store_true",
                   help="no progress output and no reasons (failures are still printed)")

    p = sub.add_parser("status", help="per stage: tasks cached and to run, with reasons",
                       description="Show what is cached and what a run would execute, and why.")
    _common(p)
    p.add_argument("--json", action="store_true", help="print JSON")

    p = sub.add_parser("sweep", help="run a parameter grid and tabulate the final metrics",
                       description="Run every point of a parameter grid (resumable) and print a table of metrics.")
    _common(p)
    _selection(p, "run every grid point of")
    p.add_argument("--grid", action="append", required=True, metavar="KEY=V1,V2,...",
                   help="a grid axis; repeat for a product of axes")
    p.add_argument("--workers", type=_workers, default=2, help=f"local worker processes, 0..{MAX_WORKERS}")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--dry-run", action="store_true",
                   help="check every grid point and list what each would run; run nothing")
    p.add_argument("--metrics", default=None, metavar="A,B,...",
                   help="the metric columns printed (dotted keys or patterns such as 'accuracy.*'; default: the "
                        "headline measures)")
    p.add_argument("--csv", default=None, metavar="PATH", type=_output_file("table.csv"),
                   help="also write the full table (every scalar metric) to PATH (.json: JSON)")
    p.add_argument("--quiet", action="store_true", help="no progress output (failures are still printed)")

    p = sub.add_parser("results", help="print the final metrics of a configuration",
                       description="Print the metrics of a configuration (from the cache; runs nothing).")
    _common(p)
    p.add_argument("--json", action="store_true", help="print JSON")

    p = sub.add_parser("gc", help="remove cache entries of these pipelines that they no longer reach",
                       description="Delete cache entries that none of the given pipelines (and their recorded "
                                   "sweeps) reaches. By default only entries that belong to them (that their "
                                   "recorded runs used) are removed: other pipelines sharing the cache keep theirs.")
    p.add_argument("pipelines", nargs="+", help="pipelines whose results to keep")
    p.add_argument("--cache", default=None, metavar="DIR|URL", help="the cache folder or s3:// URL of the pipelines")
    p.add_argument("--dry-run", action="store_true",
                   help="only report what would be removed, and which pipeline it belongs to")
    p.add_argument("--all", dest="everything", action="store_true",
                   help="also remove entries of other pipelines and entries no recorded run used (everything "
                        "the given pipelines do not reach)")
    p.add_argument("--no-keep-sweeps", action="store_true", help="also remove results of recorded sweeps")

    p = sub.add_parser("report", help="write a self-contained HTML report of a pipeline's results",
                       description="Write one self-contained HTML file: figures, metrics, sweeps, provenance.")
    _common(p)
    p.add_argument("--out", default=None, metavar="FILE", type=_output_file("report.html"),
                   help="the HTML file (default: OUTPUT/report.html)")
    p.add_argument("--results", default=None, metavar="OUTPUT",
                   help="the output folder whose published figures the report shows (as given to run --out; "
                        "default: the pipeline's output:)")

    p = sub.add_parser("functions", help="list the functions a pipeline may name",
                       description="List registered stage functions with their inputs and parameters.")
    p.add_argument("--json", action="store_true")
    return parser


def parse(argv=None) -> argparse.Namespace:
    """The command line as parsed; target stages may also follow options (``run p.yaml --set a=1 STAGE``)."""
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra and (not hasattr(args, "targets") or any(a.startswith("-") for a in extra)):
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    if hasattr(args, "targets"):
        args.targets = list(dict.fromkeys(args.targets + extra + args.until))
    return args


def main(argv=None) -> int:
    """The ``stages`` console script and ``python -m stages``: returns the exit code."""
    args = parse(argv)
    configure_logging()
    try:
        return _dispatch(args)
    except PipelineError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except UserError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # output piped into `head` and closed early
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return 0
    except KeyboardInterrupt:
        print("interrupted: everything finished so far is kept in the cache; run again to resume", file=sys.stderr)
        return 130
    except OSError as exc:  # a folder that cannot be written, a disk that is full, ...
        if isinstance(exc, TimeoutError) and not exc.filename:   # dask or a storage server did not answer
            print(f"error: no answer in time ({exc or 'timed out'})\n  fix: check that the machine is not "
                  "overloaded and any --scheduler or storage server is up, then run again: every finished result "
                  "is kept in the cache", file=sys.stderr)
            return 1
        where = f" {exc.filename}" if exc.filename else ""
        print(f"error: cannot access{where}: {exc.strerror or exc}\n  fix: check the path, its permissions and "
              "free space (every finished result is kept in the cache)", file=sys.stderr)
        return 1


def _dispatch(args) -> int:
    from . import api

    if args.command == "run":
        try:
            summary = api.run(args.pipeline, args.sets, workers=args.workers, scheduler=args.scheduler,
                                 dry=args.dry_run, cache_dir=args.cache, output_dir=args.out, quiet=args.quiet,
                                 summary_json=args.summary_json, targets=args.targets, force=args.force)
        except api.RunFailed as exc:
            if not args.quiet:
                _print_summary(exc.summary)
            print(f"error: {len(exc.summary['failures'])} task(s) failed; the rest is stored. "
                  "Fix the inputs and run again: only what is missing will run.", file=sys.stderr)
            return 1
        if not args.dry_run and not args.quiet:
            _print_summary(summary)
        return 0
    if args.command == "status":
        rows = api.status(args.pipeline, args.sets, args.cache)
        if args.json:
            print(json.dumps(rows, indent=2))
        else:
            for r in rows:
                if r.get("skipped"):
                    print(f"{r['stage']:<20} {r['fanout']:<5} skipped: {r['skipped']}")
                    continue
                print(f"{r['stage']:<20} {r['fanout']:<5} {r['cached']:>6}/{r['tasks']:<6} cached"
                      f"   {'?' if r['to_run'] is None else r['to_run']} to run" + (f": {'; '.join(r['reasons'])[:200]}" if r["reasons"] else ""))
        return 0
    if args.command == "sweep":
        result = api.sweep(args.pipeline, args.grid, args.sets, workers=args.workers, scheduler=args.scheduler,
                           cache_dir=args.cache, quiet=args.quiet, dry=args.dry_run, targets=args.targets,
                           force=args.force,
                           metric_keys=[m.strip() for m in args.metrics.split(",") if m.strip()] if args.metrics else None)
        if args.dry_run:
            for row in result["dry_run"]:
                point = " ".join(f"{k}={v}" for k, v in row["point"].items())
                print(f"== {point}: {row['to_run']} task(s) would run")
                print("\n".join("   " + line for line in row["report"].splitlines()))
            return 0
        if args.json:
            print(json.dumps(result, indent=2, default=str))
        else:
            print(api.format_table(result["rows"], result.get("headline")))
            if result.get("figure"):
                print(f"figure: {result['figure']}")
        if args.csv:
            print(f"table: {api.write_table(result['rows'], args.csv)}")
        for f in result["failures"]:
            print(f"FAILED {f['stage']}[{f['item']}]: {f['error']}", file=sys.stderr)
        return 1 if result["failures"] else 0
    if args.command == "results":
        plan = api.plan_pipeline(args.pipeline, args.sets, args.cache, None, quiet=True)
        m = api.metrics(plan)
        if args.json:
            print(json.dumps(m, indent=2, default=str))
        else:
            if "_not_computed" in m:
                print(f"not computed yet: {', '.join(m['_not_computed'])} (run: python -m stages run "
                      f"{args.pipeline})")
            for stage, why in m.get("_skipped", {}).items():
                print(f"skipped: {stage} ({why})")
            for stage, items in m.get("_left_out", {}).items():
                print(f"{stage} left out {len(items)} failed item(s): "
                      + "; ".join(f"{x['item']}: {x['why']}" for x in items)[:500])
            from .headline import headline_first
            from .results import format_results

            pairs, n_headline = headline_first(plan, m)
            if pairs:
                print(format_results(pairs, n_headline))
            for stage, warnings in m.get("_warnings", {}).items():
                for w in warnings:
                    print(f"warning ({stage}): {w}")
        return 0 if "_not_computed" not in m else 3
    if args.command == "gc":
        res = api.gc(args.pipelines, args.cache, dry=args.dry_run, keep_sweeps=not args.no_keep_sweeps,
                     everything=args.everything)
        verb = "would remove" if res["dry_run"] else "removed"
        if res["dry_run"]:
            for line in _gc_groups(res):
                print(line)
        print(f"{verb} {res['removed']} entr{'y' if res['removed'] == 1 else 'ies'} and "
              f"{res['generated_removed']} generated dataset(s), {res['bytes_freed'] / 2**20:.1f} MiB; "
              f"kept {res['kept']}" + (f" ({res['others_kept']} of other pipelines or of none recorded: --all "
                                       "removes them)" if res["others_kept"] else ""))
        return 0
    if args.command == "report":
        from .report import write_report

        path = write_report(args.pipeline, args.sets, cache_dir=args.cache, out=args.out, output_dir=args.results)
        print(path)
        return 0
    if args.command == "functions":
        from . import registry

        rows = []
        for name in registry.names():
            fn = registry.get(name)
            rows.append({"name": name, "kind": fn.kind, "fanout": fn.fanout, "inputs": list(fn.inputs),
                         "params": {k: repr(p.default) for k, p in fn.params.items()},
                         "doc": first_sentence(fn.doc or "")})
        if args.json:
            print(json.dumps(rows, indent=2))
        else:
            import shutil
            import textwrap

            width = max(40, shutil.get_terminal_size((100, 24)).columns)
            for r in rows:
                params = ", ".join(f"{k}={v}" for k, v in r["params"].items())
                print(textwrap.fill(f"{r['name']:<32} {r['fanout']:<5} inputs({', '.join(r['inputs'])}) "
                                    f"params({params})", width, subsequent_indent=" " * 8, break_on_hyphens=False))
                if r["doc"]:
                    print(textwrap.fill(r["doc"], width, initial_indent="    ", subsequent_indent="    "))
        return 0
    return 2


def _gc_groups(res: dict) -> list[str]:
    """The entries a gc dry run would remove, one line per pipeline and stage: how many, MiB, whose."""
    groups: dict[tuple[str, str], list[int]] = {}
    for e in res["entries"]:
        groups.setdefault((", ".join(e["pipelines"]), e["stage"]), []).append(e["bytes"])
    lines = [f"  {len(b):>5} entr{'y' if len(b) == 1 else 'ies'} of stage {stage:<20} {sum(b) / 2**20:8.1f} MiB  "
             f"pipeline {who}" for (who, stage), b in sorted(groups.items())]
    lines += [f"  generated dataset {g['name']}  pipeline {', '.join(g['pipelines'])}" for g in res["generated"]]
    return lines


def first_sentence(doc: str) -> str:
    """The first sentence of a docstring's first paragraph, whole (its lines joined), ending with its period."""
    paragraph = " ".join(doc.strip().split("\n\n")[0].split())
    for i, ch in enumerate(paragraph):
        if ch in ".!?" and (i + 1 == len(paragraph) or paragraph[i + 1] == " ") and not paragraph[:i].endswith(
                ("e.g", "i.e", "etc", "vs")):
            return paragraph[:i + 1]
    return paragraph


def _print_summary(summary: dict) -> None:
    print(f"{'stage':<22}{'tasks':>7}{'run':>7}{'cached':>8}{'failed':>8}{'seconds':>10}")
    for name, s in summary["stages"].items():
        print(f"{name:<22}{s['tasks']:>7}{s['executed']:>7}{s['cached']:>8}{s['failed']:>8}{s['seconds']:>10.2f}"
              + (f"   skipped: {s['skipped_stage']}" if s.get("skipped_stage") else ""))
    print(f"done in {summary['wall_seconds']:.1f}s; {summary['published']} file(s) published")
