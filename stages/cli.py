"""Command-line interface: run, status, sweep, results, gc, report, functions."""
from __future__ import annotations

import argparse
import json
import os
import sys

from .errors import PipelineError

EPILOG = """examples:
  python -m stages run pipeline.yaml
  python -m stages run pipeline.yaml --set mrf.sigma=0.5 --dry-run     # what would rerun, and why
  python -m stages sweep pipeline.yaml --grid align_mrf.sigma_scale=0.5,1,2
  python -m stages results pipeline.yaml --json
"""


def _common(p: argparse.ArgumentParser, sets: bool = True) -> None:
    p.add_argument("pipeline", help="the pipeline YAML file")
    if sets:
        p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                       help="override a parameter: a.b=v sets params.a.b; STAGE.PARAM=v sets a stage's param")
    p.add_argument("--cache", default=None, help="cache folder (default: the pipeline's 'cache:' or ./cache)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m stages", description=(
        "Declarative, cached, parallel pipelines for shape alignment and correspondence."),
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("run", help="run a pipeline (only what changed is recomputed)",
                       description="Run a pipeline: compute the cache misses under dask, publish outputs.")
    _common(p)
    p.add_argument("--dry-run", action="store_true", help="list what would execute and why; run nothing")
    p.add_argument("--workers", type=int, default=2,
                   help="local worker processes (default 2); 0 runs in this process without dask")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a dask.distributed scheduler address, e.g. tcp://10.0.0.5:8786")
    p.add_argument("--out", default=None, help="output folder (default: the pipeline's 'output:')")
    p.add_argument("--summary-json", default=None, metavar="PATH",
                   help="write per-stage tasks executed / cached / seconds as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress output")

    p = sub.add_parser("status", help="per stage: tasks cached and to run, with reasons",
                       description="Show what is cached and what a run would execute, and why.")
    _common(p)
    p.add_argument("--json", action="store_true", help="print JSON")

    p = sub.add_parser("sweep", help="run a parameter grid and tabulate the final metrics",
                       description="Run every point of a parameter grid (resumable) and print a table of metrics.")
    _common(p)
    p.add_argument("--grid", action="append", required=True, metavar="KEY=V1,V2,...",
                   help="a grid axis; repeat for a product of axes")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--scheduler", default=None, metavar="ADDRESS")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--quiet", action="store_true")

    p = sub.add_parser("results", help="print the final metrics of a configuration",
                       description="Print the metrics of a configuration (from the cache; runs nothing).")
    _common(p)
    p.add_argument("--json", action="store_true", help="print JSON")

    p = sub.add_parser("gc", help="remove cache entries no given pipeline reaches",
                       description="Delete cache entries that none of the given pipelines (and their recorded "
                                   "sweeps) reaches.")
    p.add_argument("pipelines", nargs="+", help="pipelines whose results to keep")
    p.add_argument("--cache", default=None)
    p.add_argument("--dry-run", action="store_true", help="only report what would be removed")
    p.add_argument("--no-keep-sweeps", action="store_true", help="also remove results of recorded sweeps")

    p = sub.add_parser("report", help="write a self-contained HTML report of a pipeline's results",
                       description="Write one self-contained HTML file: figures, metrics, sweeps, provenance.")
    _common(p)
    p.add_argument("--out", default=None, metavar="FILE", help="the HTML file (default: OUTPUT/report.html)")

    p = sub.add_parser("functions", help="list the functions a pipeline may name",
                       description="List registered stage functions with their inputs and parameters.")
    p.add_argument("--json", action="store_true")
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return _dispatch(args)
    except PipelineError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into `head` and closed early
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return 0
    except KeyboardInterrupt:
        print("interrupted: everything finished so far is kept in the cache; run again to resume", file=sys.stderr)
        return 130


def _dispatch(args) -> int:
    from . import runner

    if args.command == "run":
        try:
            summary = runner.run(args.pipeline, args.sets, workers=args.workers, scheduler=args.scheduler,
                                 dry=args.dry_run, cache_dir=args.cache, output_dir=args.out, quiet=args.quiet,
                                 summary_json=args.summary_json)
        except runner.RunFailed as exc:
            print(f"error: {len(exc.summary['failures'])} task(s) failed; the rest is stored. "
                  "Fix the inputs and run again: only what is missing will run.", file=sys.stderr)
            return 1
        if not args.dry_run and not args.quiet:
            _print_summary(summary)
        return 0
    if args.command == "status":
        rows = runner.status(args.pipeline, args.sets, args.cache)
        if args.json:
            print(json.dumps(rows, indent=2))
        else:
            for r in rows:
                print(f"{r['stage']:<20} {r['fanout']:<5} {r['cached']:>6}/{r['tasks']:<6} cached"
                      f"   {r['to_run']} to run" + (f": {'; '.join(r['reasons'])[:200]}" if r["reasons"] else ""))
        return 0
    if args.command == "sweep":
        result = runner.sweep(args.pipeline, args.grid, args.sets, workers=args.workers, scheduler=args.scheduler,
                              cache_dir=args.cache, quiet=args.quiet)
        if args.json:
            print(json.dumps(result, indent=2, default=str))
        else:
            print(runner.format_table(result["rows"]))
            if result.get("figure"):
                print(f"figure: {result['figure']}")
        for f in result["failures"]:
            print(f"FAILED {f['stage']}[{f['item']}]: {f['error']}", file=sys.stderr)
        return 1 if result["failures"] else 0
    if args.command == "results":
        plan = runner.plan_pipeline(args.pipeline, args.sets, args.cache, None, quiet=True)
        m = runner.metrics(plan)
        if args.json:
            print(json.dumps(m, indent=2, default=str))
        else:
            if "_not_computed" in m:
                print(f"not computed yet: {', '.join(m['_not_computed'])} (run: python -m stages run "
                      f"{args.pipeline})")
            for k, v in runner.scalar_metrics(m).items():
                print(f"{k:<40} {v:.4g}" if isinstance(v, float) else f"{k:<40} {v}")
        return 0 if "_not_computed" not in m else 3
    if args.command == "gc":
        res = runner.gc(args.pipelines, args.cache, dry=args.dry_run, keep_sweeps=not args.no_keep_sweeps)
        verb = "would remove" if res["dry_run"] else "removed"
        print(f"{verb} {res['removed']} entr{'y' if res['removed'] == 1 else 'ies'} and "
              f"{res['generated_removed']} generated dataset(s), {res['bytes_freed'] / 2**20:.1f} MiB; "
              f"kept {res['kept']}")
        return 0
    if args.command == "report":
        from .report import write_report

        path = write_report(args.pipeline, args.sets, cache_dir=args.cache, out=args.out)
        print(path)
        return 0
    if args.command == "functions":
        from . import registry

        rows = []
        for name in registry.names():
            fn = registry.get(name)
            rows.append({"name": name, "kind": fn.kind, "fanout": fn.fanout, "inputs": list(fn.inputs),
                         "params": {k: repr(p.default) for k, p in fn.params.items()},
                         "doc": fn.doc.splitlines()[0] if fn.doc else ""})
        if args.json:
            print(json.dumps(rows, indent=2))
        else:
            for r in rows:
                params = ", ".join(f"{k}={v}" for k, v in r["params"].items())
                print(f"{r['name']:<32} {r['fanout']:<5} inputs({', '.join(r['inputs'])}) params({params})")
                if r["doc"]:
                    print(f"    {r['doc']}")
        return 0
    return 2


def _print_summary(summary: dict) -> None:
    print(f"{'stage':<22}{'tasks':>7}{'run':>7}{'cached':>8}{'failed':>8}{'seconds':>10}")
    for name, s in summary["stages"].items():
        print(f"{name:<22}{s['tasks']:>7}{s['executed']:>7}{s['cached']:>8}{s['failed']:>8}{s['seconds']:>10.2f}")
    print(f"done in {summary['wall_seconds']:.1f}s; {summary['published']} file(s) published")
