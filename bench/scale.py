"""Scale benchmark: the alignment pipeline (pipelines/scale.yaml) on generated chairs at growing N.

    python bench/scale.py                      # N = 100, 300, 1000: cold time per stage, peak memory, exponents
    python bench/scale.py --sizes 100 300      # other sizes
    python bench/scale.py --knn 10             # + kNN accuracy vs the complete graph (spectral and LH), reusing
                                               #   the cached pairs of the runs above (only solve/evaluate rerun)
    python bench/scale.py --n 5000             # MRF-only memory check on a synthesized C (see below)

Each size is a cold run in its own cache folder (under --work, default /tmp/scale_bench) of
``python -m stages run pipelines/scale.yaml --set n=N --workers 2``; memory is sampled with psutil every
0.2 s over the run process and all its children (dask workers): "peak total" is the largest sum of RSS,
"peak proc" the largest single process. Stage seconds are the engine's per-stage sums of task seconds (CPU-ish
time summed over the workers, so fan-out stages take about seconds/2 of wall time on 2 workers); wall is the
whole command (generation, dask start-up, publishing included). Growth exponents are log-log least-squares
slopes over the sizes. No assertions: this prints a table (and writes --json if given).

``--n 5000``: rendering 5,000 chairs takes too long on the shared 2-core machine, so C is synthesized: planted
rotations of one random base feature plus noise (D=128 features), computed tile by tile with
``pair_costs.pair_costs`` into one (N, N, V) float32 array (the layout the engine's pair stage assembles),
then the solve stage's work (auto sigma, kNN graph, operator, spectral sync / LH, energy) in a fresh process
per configuration; peak RSS is ru_maxrss of that process (includes C).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil

ROOT = Path(__file__).resolve().parents[1]
PIPELINE = ROOT / "pipelines" / "scale.yaml"
STAGES = ("views", "hog", "pairs", "solve", "evaluate")


def _cli(args: list[str], cwd: Path) -> list[str]:
    return [sys.executable, "-m", "stages", *args]


def run_sampled(cmd: list[str], cwd: Path, period: float = 0.2) -> dict:
    """Run cmd, sampling RSS of it and its children; returns {wall, peak_total_mb, peak_proc_mb, returncode}."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.time()
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ps = psutil.Process(proc.pid)
    peak_total = peak_proc = 0
    while proc.poll() is None:
        try:
            procs = [ps] + ps.children(recursive=True)
            rss = []
            for p in procs:
                try:
                    rss.append(p.memory_info().rss)
                except psutil.Error:
                    pass
            peak_total = max(peak_total, sum(rss))
            peak_proc = max(peak_proc, max(rss, default=0))
        except psutil.Error:
            pass
        time.sleep(period)
    out, err = proc.communicate()
    return {"wall": time.time() - t0, "peak_total_mb": peak_total / 2**20, "peak_proc_mb": peak_proc / 2**20,
            "returncode": proc.returncode, "stderr": err[-2000:], "stdout": out[-2000:]}


def results_json(n: int, cache: Path, sets: list[str]) -> dict:
    cmd = _cli(["results", str(PIPELINE), "--set", f"n={n}", *sum((["--set", s] for s in sets), []),
                "--cache", str(cache), "--json"], ROOT)
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    return json.loads(res.stdout) if res.returncode == 0 else {}


def bench_size(n: int, work: Path, workers: int, keep: bool) -> dict:
    """One cold run at size n in its own cache folder."""
    cache, out = work / f"cache_{n}", work / f"out_{n}"
    if not keep:
        shutil.rmtree(cache, ignore_errors=True)
    summary = work / f"summary_{n}.json"
    cmd = _cli(["run", str(PIPELINE), "--set", f"n={n}", "--cache", str(cache), "--out", str(out),
                "--workers", str(workers), "--summary-json", str(summary), "--quiet"], ROOT)
    r = run_sampled(cmd, ROOT)
    if r["returncode"] != 0:
        raise SystemExit(f"run at n={n} failed:\n{r['stderr']}")
    s = json.loads(summary.read_text())
    m = results_json(n, cache, [])
    return {"n": n, "wall": r["wall"], "peak_total_mb": r["peak_total_mb"], "peak_proc_mb": r["peak_proc_mb"],
            "stages": {k: s["stages"][k]["seconds"] for k in STAGES},
            "exact": m.get("ground_truth", {}).get("exact")}


def growth_exponents(rows: list[dict]) -> dict:
    """Log-log least-squares slope of each stage's seconds (and wall) against N."""
    n = np.log([r["n"] for r in rows])
    out = {}
    for key in STAGES + ("wall",):
        t = np.array([r["stages"][key] if key in STAGES else r[key] for r in rows], dtype=float)
        out[key] = float(np.polyfit(n, np.log(np.maximum(t, 1e-4)), 1)[0]) if len(rows) >= 2 else float("nan")
    return out


def knn_accuracy(n: int, work: Path, knn: int) -> list[dict]:
    """ground_truth.exact of spectral and LH on the complete graph and on the kNN graph (cached pairs reused)."""
    rows = []
    cache, out = work / f"cache_{n}", work / f"out_{n}"
    for solver in ("spectral", "lh"):
        for k in (0, knn):
            sets = [f"solver={solver}", f"knn={k}"]
            cmd = _cli(["run", str(PIPELINE), "--set", f"n={n}", *sum((["--set", s] for s in sets), []),
                        "--cache", str(cache), "--out", str(out / f"{solver}_{k}"), "--workers", "1",
                        "--summary-json", str(work / "knn_summary.json"), "--quiet"], ROOT)
            r = run_sampled(cmd, ROOT)
            if r["returncode"] != 0:
                raise SystemExit(f"knn run failed:\n{r['stderr']}")
            s = json.loads((work / "knn_summary.json").read_text())["stages"]
            gt = results_json(n, cache, sets).get("ground_truth", {})
            rows.append({"n": n, "solver": solver, "knn": k, "exact": gt.get("exact"),
                         "within_one": gt.get("within_one_view"), "solve_s": s["solve"]["seconds"],
                         "evaluate_s": s["evaluate"]["seconds"], "pairs_cached": s["pairs"]["executed"] == 0})
    return rows


def print_table(rows: list[dict], exps: dict) -> None:
    head = f"{'N':>6} " + " ".join(f"{k:>9}" for k in STAGES) + f" {'wall':>8} {'peak tot':>9} {'peak proc':>9} {'exact':>6}"
    print("cold run, seconds (stage = sum of task seconds over workers), memory in MB")
    print(head)
    for r in rows:
        print(f"{r['n']:>6} " + " ".join(f"{r['stages'][k]:>9.2f}" for k in STAGES)
              + f" {r['wall']:>8.1f} {r['peak_total_mb']:>9.0f} {r['peak_proc_mb']:>9.0f} {r['exact']!s:>6}")
    print(f"{'slope':>6} " + " ".join(f"{exps[k]:>9.2f}" for k in STAGES) + f" {exps['wall']:>8.2f}")


def synth_features(n: int, V: int = 16, D: int = 128, noise: float = 0.6, seed: int = 0):
    """Planted rotations of one base (V, D) feature plus noise: F (n, V, D) float32, offsets (n,)."""
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(V, D))
    offsets = rng.integers(0, V, size=n)
    idx = (np.arange(V)[None, :] - offsets[:, None]) % V  # F_i[(v + o_i) % V] = base[v]
    F = base[idx] + noise * rng.normal(size=(n, V, D))
    return F.astype(np.float32), offsets


def synth_costs(n: int, path: Path, tile: int = 500) -> dict:
    """Synthesize C (n, n, V) float32 tile by tile with pair_costs.pair_costs (upper tiles + mirror, like the
    engine's pair stage) and save it with the planted offsets; returns timing and peak RSS of this process."""
    import resource

    from corr_core.alignment import pair_costs

    t0 = time.time()
    F, offsets = synth_features(n)
    C = np.empty((n, n, F.shape[1]), dtype=np.float32)
    for a in range(0, n, tile):
        for b in range(a, n, tile):
            block = pair_costs.pair_costs(F[a:a + tile], F[b:b + tile])
            C[a:a + tile, b:b + tile] = block
            if b != a:
                C[b:b + tile, a:a + tile] = pair_costs.mirror_pair_costs(block)
    seconds = time.time() - t0
    np.save(path, C)
    np.save(str(path) + ".offsets.npy", offsets)
    return {"pairs_s": seconds, "C_mb": C.nbytes / 2**20,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def _child_mrf(path: str, solver: str, knn: int) -> dict:
    """In a fresh process: load C (as the solve stage receives it), then the solve stage's work (auto sigma,
    kNN graph, operator, spectral sync or LH, energy); report times and ru_maxrss (C included)."""
    import resource

    from corr_core import mrf
    from corr_core.alignment import azimuth, solvers, sync
    from corr_core.alignment.circulant import CirculantPairwise

    C = np.load(path)
    offsets = np.load(path + ".offsets.npy")
    n, V = C.shape[0], C.shape[2]
    rss_after_c = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.time()
    sigma = solvers.choose_sigma(C)
    neighbors = solvers.knn_neighbors(C, knn)
    op = CirculantPairwise(C, sigma, neighbors)
    t_op = time.time() - t0
    t0 = time.time()
    unary = solvers.uniform_unary(n, V, 0)
    if solver == "spectral":
        labels = sync.spectral_sync_operator(op)
    else:
        labels = mrf.solve_lh(op, unary, compute_bound=False).labels
    e = mrf.energy(op, unary, labels)
    t_solve = time.time() - t0
    exact = azimuth.agreement_up_to_offset(labels, offsets, V)[0]
    return {"n": n, "solver": solver, "knn": knn, "C_mb": C.nbytes / 2**20, "op_mb": op.nbytes / 2**20,
            "operator_s": t_op, "solve_s": t_solve, "energy": float(e), "exact": float(exact),
            "rss_after_C_mb": rss_after_c, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def _in_child(call: str) -> dict | None:
    code = f"import json, sys; sys.path.insert(0, {str(ROOT / 'bench')!r}); import scale; print(json.dumps(scale.{call}))"
    # one BLAS thread, as in the engine's dask workers (distributed sets OMP_NUM_THREADS=1 for them)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    if res.returncode != 0:
        print(res.stderr[-2000:])
        return None
    return json.loads(res.stdout.strip().splitlines()[-1])


def bench_mrf_memory(n: int, configs: list[tuple[str, int]], work: Path) -> dict:
    path = work / f"C_{n}.npy"
    synth = _in_child(f"synth_costs({n}, {str(path)!r})")
    print(f"N={n}: synthesized C {synth['C_mb']:.0f} MB float32 in {synth['pairs_s']:.1f} s "
          f"(pair_costs, 500-shape tiles, D=128), peak RSS {synth['peak_rss_mb']:.0f} MB", flush=True)
    rows = []
    for solver, knn in configs:
        row = _in_child(f"_child_mrf({str(path)!r}, {solver!r}, {knn})")
        if row is None:
            continue
        rows.append(row)
        print(f"N={n} {solver:>8} knn={knn:>3}: operator {row['op_mb']:.0f} MB built in {row['operator_s']:.1f} s, "
              f"solve {row['solve_s']:.1f} s, peak RSS {row['peak_rss_mb']:.0f} MB (C alone {row['rss_after_C_mb']:.0f}), "
              f"exact {row['exact']:.3f}", flush=True)
    path.unlink(missing_ok=True)
    Path(str(path) + ".offsets.npy").unlink(missing_ok=True)
    return {"synth": synth, "solves": rows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="*", default=[100, 300, 1000])
    ap.add_argument("--n", type=int, default=None, help="MRF-only memory check at this N on a synthesized C")
    ap.add_argument("--mrf-configs", nargs="*", default=["spectral:0", "lh:0", "spectral:10", "lh:10"],
                    help="solver:knn pairs for --n")
    ap.add_argument("--knn", type=int, default=0, help="also measure kNN accuracy (spectral, LH) at each size")
    ap.add_argument("--knn-only", action="store_true", help="skip the timing runs (reuse their caches)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--work", default="/tmp/scale_bench")
    ap.add_argument("--json", default=None, help="write all numbers here")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    report: dict = {}
    if args.n:
        configs = [(c.split(":")[0], int(c.split(":")[1])) for c in args.mrf_configs]
        report["mrf_memory"] = bench_mrf_memory(args.n, configs, work)
    else:
        if not args.knn_only:
            rows = []
            for n in args.sizes:
                rows.append(bench_size(n, work, args.workers, keep=False))
                print(f"n={n}: done in {rows[-1]['wall']:.1f} s", flush=True)
            exps = growth_exponents(rows)
            print_table(rows, exps)
            report.update(sizes=rows, exponents=exps)
        if args.knn:
            acc = []
            for n in args.sizes:
                acc += knn_accuracy(n, work, args.knn)
            print(f"\nkNN accuracy (ground_truth.exact), k={args.knn}")
            print(f"{'N':>6} {'solver':>9} {'knn':>4} {'exact':>7} {'within1':>8} {'solve s':>8} {'eval s':>7}")
            for r in acc:
                print(f"{r['n']:>6} {r['solver']:>9} {r['knn']:>4} {r['exact']!s:>7} {r['within_one']!s:>8} "
                      f"{r['solve_s']:>8.2f} {r['evaluate_s']:>7.2f}")
            report["knn_accuracy"] = acc
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
