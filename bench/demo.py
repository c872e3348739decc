"""Cold time of the default pipeline (``pipeline.yaml``) against a baseline revision, in one run, and where its
heaviest stages spend their time.

Run: python bench/demo.py --repeats 1 --profile

Each run is ``python -m stages run pipeline.yaml --cache C --out O --summary-json S`` (2 workers, the default)
with a fresh temporary cache, so the datasets are generated inside it (part of the wall time). The baseline
(``--baseline-ref``, default c83b2ae: main on the day issue 26 was filed) is exported with ``git archive`` and
runs its own code (cwd and PYTHONPATH = that tree); the working tree runs this checkout. The runs alternate
(baseline, current, baseline, current, ... for ``--repeats N``) so a load change on the shared machine hits
both. Printed: the wall seconds of each run and the median ratio current/baseline; the generation seconds (from
the time the ``generating dataset`` line is printed to the next other line: generators plus planning again) and
the CPU seconds of the run process and its workers (less sensitive to other jobs than wall); the wall and CPU
seconds of the same command run again at once (``noop``: everything cached, nothing runs);
per stage the task seconds of the summary (``stages -> seconds``: summed over the workers) and their ratio;
whether ``python -m stages results pipeline.yaml --json`` is identical between the two (``--same-results-ref
REF``: also against one cold run of REF). ``--profile``: cProfile top 20 (cumulative) of the slowest task of each
of the 4 stages with the most task seconds, rerun in this process on the working tree's cache (inputs loaded by
``stages.worker.load_inputs``, the function called as the worker calls it; modules the function imports on its
first call in this process, as a fresh dask worker does, are in the profile).
"""
from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pstats
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import ROOT, one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()      # the profiled tasks run in this process with one BLAS thread, as in a dask worker

PIPELINE = "pipeline.yaml"
GENERATING = "generating dataset"


def export(ref: str, work: str) -> tuple[str, str]:
    """(folder holding ``git archive REF``, the commit's short id)."""
    commit = subprocess.run(["git", "rev-parse", "--short", ref], cwd=ROOT, check=True, capture_output=True,
                            text=True).stdout.strip()
    tree = os.path.join(work, f"tree-{commit}")
    os.makedirs(tree)
    archive = subprocess.Popen(["git", "archive", commit], cwd=ROOT, stdout=subprocess.PIPE)
    subprocess.run(["tar", "-x", "-C", tree], stdin=archive.stdout, check=True)
    if archive.wait():
        raise SystemExit(f"git archive {ref} failed")
    return tree, commit


def stages_cli(tree: str, args: list[str], **kw) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": tree}
    return subprocess.run([sys.executable, "-m", "stages", *args], cwd=tree, env=env, text=True, **kw)


def children_cpu() -> float:
    """User + system CPU seconds of the finished child processes (a run and its dask workers)."""
    use = resource.getrusage(resource.RUSAGE_CHILDREN)
    return use.ru_utime + use.ru_stime


def cold_run(tree: str, work: str, name: str, workers: int) -> dict:
    """One cold run of the default pipeline in ``tree``: wall and generation seconds, summary, results JSON."""
    folder = tempfile.mkdtemp(prefix=f"{name}-", dir=work)
    cache, out, summary = (os.path.join(folder, n) for n in ("cache", "out", "summary.json"))
    cmd = [sys.executable, "-m", "stages", "run", PIPELINE, "--cache", cache, "--out", out, "--summary-json",
           summary, "--workers", str(workers)]
    cpu0 = children_cpu()
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=tree, env={**os.environ, "PYTHONPATH": tree}, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    gen_start = gen_end = None
    lines = []
    for line in proc.stdout:  # each line timed as it arrives
        now = time.perf_counter() - t0
        lines.append(line)
        if GENERATING in line:
            gen_start = now if gen_start is None else gen_start
        elif gen_start is not None and gen_end is None:
            gen_end = now
    wall = time.perf_counter() - t0
    if proc.wait():
        raise SystemExit(f"{name}: {' '.join(cmd)} failed in {tree}:\n{''.join(lines[-30:])}")
    cpu = children_cpu() - cpu0
    noop_cpu0, t1 = children_cpu(), time.perf_counter()   # the same command again: everything cached
    stages_cli(tree, ["run", PIPELINE, "--cache", cache, "--out", out, "--workers", str(workers)], check=True,
               capture_output=True)
    noop, noop_cpu = time.perf_counter() - t1, children_cpu() - noop_cpu0
    with open(summary) as f:
        stages = {k: v["seconds"] for k, v in json.load(f)["stages"].items()}
    results = stages_cli(tree, ["results", PIPELINE, "--cache", cache, "--json"], check=True,
                         capture_output=True).stdout
    gen = gen_end - gen_start if gen_start is not None and gen_end is not None else float("nan")
    print(f"  {name}: {wall:.1f} s wall, {cpu:.1f} s CPU (generation {gen:.1f} s); no-op rerun {noop:.2f} s wall, "
          f"{noop_cpu:.2f} s CPU", flush=True)
    return {"wall": wall, "cpu": cpu, "generation": gen, "noop": noop, "noop_cpu": noop_cpu, "stages": stages,
            "results": results, "cache": cache}


def leaves(value, path=""):
    """{dotted path: leaf} of a JSON value."""
    if isinstance(value, dict):
        return {k: v for key, sub in value.items() for k, v in leaves(sub, f"{path}.{key}" if path else key).items()}
    if isinstance(value, list):
        return {k: v for i, sub in enumerate(value) for k, v in leaves(sub, f"{path}[{i}]").items()}
    return {path: value}


def compare_results(a: str, b: str, what: str) -> None:
    if a == b:
        print(f"results --json, {what}: identical")
        return
    la, lb = leaves(json.loads(a)), leaves(json.loads(b))
    diff = sorted(k for k in la.keys() | lb.keys() if la.get(k, "<absent>") != lb.get(k, "<absent>"))
    print(f"results --json, {what}: differs ({len(diff)} of {len(la.keys() | lb.keys())} values), e.g. "
          + ", ".join(diff[:6]))


def ratio(a: float, b: float) -> str:
    return f"{a / b:.2f}" if b > 0 else "-"


def stage_table(base: list[dict], cur: list[dict]) -> list[tuple[str, float]]:
    """Print median task seconds per stage for both, and their ratio; returns (stage, current seconds)."""
    names = list(cur[0]["stages"]) + [n for n in base[0]["stages"] if n not in cur[0]["stages"]]
    med = lambda runs, n: statistics.median(r["stages"].get(n, 0.0) for r in runs)  # noqa: E731
    print(f"\n{'stage':<20} {'baseline s':>10} {'current s':>10} {'ratio':>6}")
    rows = []
    for n in names:
        b, c = med(base, n), med(cur, n)
        rows.append((n, c))
        print(f"{n:<20} {b:>10.2f} {c:>10.2f} {ratio(c, b):>6}")
    b, c = (sum(med(runs, n) for n in names) for runs in (base, cur))
    print(f"{'total':<20} {b:>10.2f} {c:>10.2f} {ratio(c, b):>6}")
    return rows


def profile_stage(cache: str, stage: str, top: int = 20) -> None:
    """cProfile of the slowest task of ``stage`` (by its recorded seconds), rerun here on the cached inputs."""
    from stages import api, registry
    from stages.worker import load_inputs
    plan = api.plan_pipeline(os.path.join(ROOT, PIPELINE), cache_dir=cache, quiet=True)
    tasks = plan.stages[stage].tasks
    seconds = {t.key: ((plan.store.manifest(t.key) or {}).get("info") or {}).get("seconds", 0.0) for t in tasks}
    task = max(tasks, key=lambda t: seconds[t.key])
    fn = registry.get(task.function)
    inputs = load_inputs(plan.store, task.inputs)
    kwargs = dict(task.params)
    if "item_name" in fn.engine_args:
        kwargs["item_name"] = task.item_name
    out_dir = plan.store.tmp_dir() if "out_dir" in fn.engine_args else None
    if out_dir:
        kwargs["out_dir"] = out_dir
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.runcall(fn.func, **inputs, **kwargs)
    took = time.perf_counter() - t0
    if out_dir:
        shutil.rmtree(out_dir, ignore_errors=True)
    print(f"\n=== {task.display} ({task.function}): {seconds[task.key]:.2f} s in the run, {took:.2f} s profiled "
          f"(slowest of {len(tasks)} task(s))")
    text = io.StringIO()
    pstats.Stats(prof, stream=text).strip_dirs().sort_stats("cumulative").print_stats(top)
    body = text.getvalue()
    print(body[body.find("   ncalls"):].rstrip())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline-ref", default="c83b2ae", help="git ref of the baseline (default: %(default)s)")
    ap.add_argument("--repeats", type=int, default=1, help="baseline/current pairs, interleaved (default 1)")
    ap.add_argument("--workers", type=int, default=2, help="run --workers (default 2)")
    ap.add_argument("--profile", action="store_true", help="cProfile one task of each of the 4 heaviest stages")
    ap.add_argument("--same-results-ref", default=None, metavar="REF",
                    help="also compare the results with one cold run of REF")
    ap.add_argument("--work", default=None, help="folder for the trees and caches (default: a temporary one)")
    args = ap.parse_args()
    if args.work:
        if os.path.exists(args.work) and not os.path.isdir(args.work):
            ap.error(f"--work {args.work}: is a file, not a folder; name a folder (made when missing)")
        os.makedirs(args.work, exist_ok=True)   # a new folder given by name is made, as the caches under it
    work = tempfile.mkdtemp(prefix="bench_demo_", dir=args.work)
    try:
        base_tree, base_commit = export(args.baseline_ref, work)
        head = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, capture_output=True,
                              text=True).stdout.strip()
        print(f"cold runs of {PIPELINE}, {args.workers} workers: baseline {base_commit} ({args.baseline_ref}) vs "
              f"working tree {head}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
              f"load average {os.getloadavg()[0]:.1f}", flush=True)
        base, cur = [], []
        for i in range(args.repeats):
            base.append(cold_run(base_tree, work, f"baseline-{i + 1}", args.workers))
            cur.append(cold_run(ROOT, work, f"current-{i + 1}", args.workers))
        print(f"\nmedians of {args.repeats} (load average now {os.getloadavg()[0]:.1f}):")
        for what in ("wall", "cpu", "generation", "noop", "noop_cpu"):
            b, c = (statistics.median(r[what] for r in runs) for runs in (base, cur))
            print(f"  {what + ' s':<13} baseline {b:7.2f}  current {c:7.2f}  ratio {ratio(c, b)}")
        rows = stage_table(base, cur)
        print()
        compare_results(base[0]["results"], cur[0]["results"], f"current vs baseline {base_commit}")
        if args.repeats > 1:
            same = all(r["results"] == cur[0]["results"] for r in cur)
            print(f"results --json, current runs among themselves: {'identical' if same else 'differs'}")
        if args.same_results_ref:
            tree, commit = export(args.same_results_ref, work)
            other = cold_run(tree, work, f"results-{commit}", args.workers)
            compare_results(other["results"], cur[0]["results"], f"current vs {commit} ({args.same_results_ref})")
        if args.profile:
            for stage, _ in sorted(rows, key=lambda r: -r[1])[:4]:
                profile_stage(cur[-1]["cache"], stage)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
