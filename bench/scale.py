"""Scale benchmark: the alignment pipeline (pipelines/scale.yaml) on generated chairs at growing N, and its pair
and solve stages on synthesized features up to N = 100,000.

    python bench/scale.py                      # N = 100, 300, 1000: cold time per stage, peak memory, exponents
    python bench/scale.py --sizes 2000         # other sizes (candidate graph, the default of scale.yaml)
    python bench/scale.py --sizes 1000 --compare-complete   # + the complete graph through the same stages
                                               #   (views/hog reused from the cache; accuracy and pairs computed)
    python bench/scale.py --synthetic 10000 30000 100000    # candidate graph on synthesized features
    python bench/scale.py --n 5000             # complete-graph MRF memory check on a synthesized dense C
    python bench/scale.py --descriptor-quality 500    # recall of the true nearest shapes per descriptor
    python bench/scale.py --index-speed 10000 100000  # k-NN index CPU time: kd-tree, faiss flat, faiss HNSW

Each size is a cold run in its own cache folder (under --work, default /tmp/scale_bench) of
``python -m stages run pipelines/scale.yaml --set n=N --workers 2``; memory is sampled with psutil every
0.2 s over the run process and all its children (dask workers): "peak total" is the largest sum of RSS,
"peak proc" the largest single process. Stage seconds are the engine's per-stage sums of task seconds (summed
over the workers, so fan-out stages take about seconds/2 of wall time on 2 workers); wall is the whole command
(generation, dask start-up, publishing included). Growth exponents are log-log least-squares slopes over the
sizes. No assertions: this prints a table (and writes --json if given).

``--synthetic``: features are synthesized (planted rotations of one random (V=16, D=128) base feature plus
noise), then each stage of the candidate-graph path runs in a fresh process (one BLAS thread), as the pipeline's
stages do, on the previous stage's saved output: descriptors + candidate graph (+ self costs), pair costs of the
candidate pairs grouped like the engine's tasks (by 32-shape block of the lower shape), solve (spectral on the
sparse graph, symmetry, continuous refinement), evaluate (scale.yaml's settings). Per stage: CPU seconds
(process_time), wall seconds and peak RSS (ru_maxrss, inputs included); exponents over the sizes.

``--n 5000``: C is synthesized densely (the complete graph), computed tile by tile with ``pair_costs.pair_costs``
into one (N, N, V) float32 array (the layout the engine's complete pair stage assembles), then the solve stage's
work (auto sigma, kNN graph, operator, spectral sync / LH, energy) in a fresh process per configuration; peak RSS
is ru_maxrss of that process (includes C).
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
sys.path.insert(0, str(ROOT))  # corr_core / shapecorr from this checkout (the in-process benchmarks)
PIPELINE = ROOT / "pipelines" / "scale.yaml"
STAGES = ("views", "hog", "descriptor", "candidates", "pairs", "solve", "evaluate")
SYNTH_STAGES = ("candidates", "pairs", "solve", "evaluate")


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


def bench_size(n: int, work: Path, workers: int, keep: bool, sets: list[str] = (), tag: str = "") -> dict:
    """One run at size n in its own cache folder (cold unless ``keep``); sets: extra ``--set`` assignments."""
    cache, out = work / f"cache_{n}", work / f"out_{n}{tag}"
    if not keep:
        shutil.rmtree(cache, ignore_errors=True)
    summary = work / f"summary_{n}{tag}.json"
    extra = sum((["--set", x] for x in sets), [])
    cmd = _cli(["run", str(PIPELINE), "--set", f"n={n}", *extra, "--cache", str(cache), "--out", str(out),
                "--workers", str(workers), "--summary-json", str(summary), "--quiet"], ROOT)
    r = run_sampled(cmd, ROOT)
    if r["returncode"] != 0:
        raise SystemExit(f"run at n={n} failed:\n{r['stderr']}")
    s = json.loads(summary.read_text())
    m = results_json(n, cache, list(sets))
    return {"n": n, "sets": list(sets), "wall": r["wall"], "peak_total_mb": r["peak_total_mb"],
            "peak_proc_mb": r["peak_proc_mb"],
            "stages": {k: s["stages"][k]["seconds"] for k in STAGES if k in s["stages"]},
            "exact": m.get("ground_truth", {}).get("exact"), "pairs_computed": m.get("pairs_computed"),
            "pairs_total": m.get("pairs_total")}


def growth_exponents(rows: list[dict], keys=STAGES + ("wall",), get=None) -> dict:
    """Log-log least-squares slope of each stage's seconds (and wall) against N."""
    get = get or (lambda r, key: r["stages"][key] if key in STAGES else r[key])
    n = np.log([r["n"] for r in rows])
    out = {}
    for key in keys:
        t = np.array([get(r, key) for r in rows], dtype=float)
        out[key] = float(np.polyfit(n, np.log(np.maximum(t, 1e-4)), 1)[0]) if len(rows) >= 2 else float("nan")
    return out


def compare_complete(n: int, work: Path, workers: int) -> dict:
    """The complete graph (``graph=complete``: every pair) through the same stages, in the cache of the
    candidate run at size n (views, hog, descriptors reused): its exact, pairs computed and stage seconds."""
    return bench_size(n, work, workers, keep=True, sets=["graph=complete"], tag="_complete")


def print_table(rows: list[dict], exps: dict) -> None:
    head = f"{'N':>6} " + " ".join(f"{k[:9]:>9}" for k in STAGES) + \
        f" {'wall':>8} {'peak tot':>9} {'peak proc':>9} {'exact':>6} {'pairs':>9} {'of all':>7}"
    print("run, seconds (stage = sum of task seconds over workers), memory in MB")
    print(head)
    for r in rows:
        frac = r["pairs_computed"] / r["pairs_total"] if r.get("pairs_total") else float("nan")
        print(f"{r['n']:>6} " + " ".join(f"{r['stages'].get(k, 0.0):>9.2f}" for k in STAGES)
              + f" {r['wall']:>8.1f} {r['peak_total_mb']:>9.0f} {r['peak_proc_mb']:>9.0f} {r['exact']!s:>6}"
              + f" {r.get('pairs_computed')!s:>9} {frac:>7.4f}  {' '.join(r.get('sets', []))}")
    if exps:
        print(f"{'slope':>6} " + " ".join(f"{exps[k]:>9.2f}" for k in STAGES) + f" {exps['wall']:>8.2f}")


# ---- the candidate-graph stages on synthesized features ---------------------------------------------------

def _stage_clock():
    """(cpu seconds, wall seconds) now."""
    return time.process_time(), time.time()


def _since(clock) -> dict:
    cpu, wall = _stage_clock()
    return {"cpu_s": cpu - clock[0], "wall_s": wall - clock[1]}


def _peak_mb() -> float:
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _child_synth_candidates(n: int, work: str, k: int, n_random: int) -> dict:
    """Synthesize features (saved), then the descriptor stage (per shape, in batches) and the candidates stage:
    pairs, kinds and self costs saved. Timed from after the synthesis."""
    from corr_core.alignment import candidates
    from corr_core.alignment.pair_costs import pair_costs_listed

    F, offsets = synth_features(n)
    np.save(f"{work}/F.npy", F)
    np.save(f"{work}/offsets.npy", offsets)
    clock = _stage_clock()
    X = np.concatenate([candidates.rotation_invariant_descriptor(F[s:s + 4096]) for s in range(0, n, 4096)])
    self_costs = np.concatenate([pair_costs_listed(F[s:s + 4096], F[s:s + 4096],
                                                   np.repeat(np.arange(len(F[s:s + 4096])), 2).reshape(-1, 2))
                                 for s in range(0, n, 4096)])
    descriptor = _since(clock)
    clock = _stage_clock()
    pairs, kind = candidates.candidate_pairs(X, k=k, n_random=n_random, seed=0, self_pairs=False)
    out = _since(clock)
    np.save(f"{work}/pairs.npy", pairs)
    np.save(f"{work}/kind.npy", kind)
    np.save(f"{work}/self_costs.npy", self_costs)
    return {**out, "descriptor_cpu_s": descriptor["cpu_s"], "peak_mb": _peak_mb(), "pairs": int(len(pairs))}


def _child_synth_pairs(work: str, tile: int = 32) -> dict:
    """The pair stage on the candidate pairs: grouped like the engine's tasks (the 32-shape block of the lower
    shape; A = its distinct first shapes, B = their distinct partners), one ``pair_costs_listed`` per task."""
    from corr_core.alignment.pair_costs import pair_costs_listed

    F = np.load(f"{work}/F.npy")
    pairs = np.load(f"{work}/pairs.npy")
    values = np.empty((len(pairs), F.shape[1]), np.float32)
    clock = _stage_clock()
    block = pairs[:, 0] // tile
    starts = np.flatnonzero(np.r_[True, block[1:] != block[:-1]])   # pairs are sorted: blocks are runs
    for s, e in zip(starts, np.r_[starts[1:], len(pairs)]):
        a, ia = np.unique(pairs[s:e, 0], return_inverse=True)
        b, ib = np.unique(pairs[s:e, 1], return_inverse=True)
        values[s:e] = pair_costs_listed(F[a], F[b], np.stack([ia, ib], axis=1))
    out = _since(clock)
    np.save(f"{work}/values.npy", values)
    return {**out, "peak_mb": _peak_mb(), "tasks": int(len(starts))}


def _graph(work: str):
    from corr_core.alignment import graph_costs

    pairs, kind = np.load(f"{work}/pairs.npy"), np.load(f"{work}/kind.npy")
    n = len(np.load(f"{work}/offsets.npy"))
    names = [f"{i:06d}" for i in range(n)]
    graph = {"names": names, "pairs": pairs, "kind": kind, "self_costs": np.load(f"{work}/self_costs.npy")}
    return graph_costs.from_candidates(names, pairs, np.load(f"{work}/values.npy"), graph), names


def _child_synth_solve(work: str, solver: str = "spectral") -> dict:
    """The solve stage on the graph costs (as align.solve: symmetry, solver, continuous refinement)."""
    import pickle

    from corr_core.alignment import azimuth, solvers

    gc, names = _graph(work)
    clock = _stage_clock()
    sol = solvers.solve_alignment(gc, solver=solver)
    out = _since(clock)
    with open(f"{work}/solution.pkl", "wb") as fh:
        pickle.dump({"names": names, **sol}, fh)
    offsets = np.load(f"{work}/offsets.npy")
    return {**out, "peak_mb": _peak_mb(), "costs_mb": gc.nbytes / 2**20,
            "exact": float(azimuth.agreement_up_to_offset(sol["labels"], offsets, gc.n_views)[0])}


def _child_synth_evaluate(work: str) -> dict:
    """The evaluate stage as pipelines/scale.yaml configures it (seeds [0], 2 restarts, 2 ICM starts, no peers)."""
    import pickle

    from corr_core.alignment import measures

    gc, names = _graph(work)
    with open(f"{work}/solution.pkl", "rb") as fh:
        sol = pickle.load(fh)
    truth = dict(zip(names, np.load(f"{work}/offsets.npy").tolist()))
    clock = _stage_clock()
    m = measures.evaluate_alignment(gc, sol, truth, seeds=[0], restarts=2, icm_starts=2, compare_solvers=False)
    return {**_since(clock), "peak_mb": _peak_mb(), "exact": m["ground_truth"]["exact"],
            "equivariance": m["equivariance"]}


def bench_synthetic(n: int, work: Path, k: int, n_random: int, evaluate: bool) -> dict:
    """The candidate-graph stages at size n on synthesized features, each in a fresh process."""
    folder = work / f"synth_{n}"
    folder.mkdir(parents=True, exist_ok=True)
    row = {"n": n, "stages": {}}
    calls = {"candidates": f"_child_synth_candidates({n}, {str(folder)!r}, {k}, {n_random})",
             "pairs": f"_child_synth_pairs({str(folder)!r})", "solve": f"_child_synth_solve({str(folder)!r})"}
    if evaluate:
        calls["evaluate"] = f"_child_synth_evaluate({str(folder)!r})"
    for stage, call in calls.items():
        res = _in_child(call)
        if res is None:
            raise SystemExit(f"synthetic {stage} at n={n} failed")
        row["stages"][stage] = res
        print(f"N={n} {stage}: " + ", ".join(f"{key} {v:.3f}" if isinstance(v, float) else f"{key} {v}"
                                               for key, v in res.items()), flush=True)
    shutil.rmtree(folder, ignore_errors=True)
    return row


def print_synthetic(rows: list[dict]) -> dict:
    stages = [s for s in SYNTH_STAGES if any(s in r["stages"] for r in rows)]
    exps = {}
    for st in stages:
        have = [r for r in rows if st in r["stages"]]
        exps.update(growth_exponents(have, (st,), lambda r, key: r["stages"][key]["cpu_s"]) if len(have) > 1
                    else {st: float("nan")})
    print("\ncandidate graph on synthesized features (V=16, D=128): CPU s / wall s / peak RSS MB per stage "
          "(candidates: descriptors + index; exponents of CPU s)")
    print(f"{'N':>7} {'pairs':>9} " + " ".join(f"{s:>22}" for s in stages) + f" {'exact':>6}")
    for r in rows:
        cells = [f"{r['stages'][s]['cpu_s']:7.1f} {r['stages'][s]['wall_s']:6.1f} {r['stages'][s]['peak_mb']:7.0f}"
                 if s in r["stages"] else "-" for s in stages]
        print(f"{r['n']:>7} {r['stages']['candidates']['pairs']:>9} " + " ".join(f"{c:>22}" for c in cells)
              + f" {r['stages']['solve']['exact']:>6.3f}")
    if exps:
        print(f"{'slope':>7} {'':>9} " + " ".join(f"{exps[s]:>22.2f}" for s in stages) + "   (of CPU s)")
    return exps


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
    unary = solvers.uniform_unary(n, V, seed=0)
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


# ---- choosing the descriptor and the index ------------------------------------------------------------------

def descriptor_quality(n: int, work: Path, k: int = 10) -> list[dict]:
    """Recall of each shape's true k nearest shapes (by min_theta C_ij, all pairs computed) among the k nearest by
    descriptor distance, for several descriptor reductions, on n generated chairs (generate.chairs seed 0, views
    and HoG as the pipeline computes them); also the median best cost of the chosen pairs."""
    from corr_core.alignment import candidates
    from corr_core.alignment.pair_costs import pair_costs
    from corr_core.generate import write_chair_collection
    from shapecorr import alignment as stages_alignment

    folder = work / f"chairs_{n}"
    if not (folder / "ground_truth.csv").exists():
        write_chair_collection(folder, n=n, seed=0, views=16)
    files = sorted(folder.glob("*.obj"))[:n]
    F = np.stack([stages_alignment.hog(stages_alignment.views([str(f)])) for f in files])
    best = np.concatenate([pair_costs(F[a:a + 100], F) for a in range(0, n, 100)]).min(axis=2).astype(np.float64)
    np.fill_diagonal(best, np.inf)
    true_nn = np.argsort(best, axis=1)[:, :k]
    variants = {"full DFT magnitudes": candidates.rotation_invariant_descriptor(F, dim=0)}
    for dim in (16, 32, 64, 128, 256):
        variants[f"projected to {dim}"] = candidates.rotation_invariant_descriptor(F, dim=dim)
    variants["128, then 32 principal components"] = candidates.principal_components(variants["projected to 128"])
    rows = [{"descriptor": "true nearest", "recall": 1.0, "median_cost": float(np.median(np.take_along_axis(best, true_nn, 1)))},
            {"descriptor": "all pairs", "recall": float("nan"), "median_cost": float(np.median(best[np.isfinite(best)]))}]
    for name, X in variants.items():
        X = X.astype(np.float64)
        sq = (X ** 2).sum(axis=1)
        D = sq[:, None] + sq[None] - 2 * X @ X.T
        np.fill_diagonal(D, np.inf)
        nn = np.argsort(D, axis=1)[:, :k]
        recall = float(np.mean([len(set(a) & set(b)) / k for a, b in zip(nn, true_nn)]))
        rows.append({"descriptor": name, "recall": recall,
                     "median_cost": float(np.median(np.take_along_axis(best, nn, 1)))})
    print(f"\ndescriptor quality on {n} generated chairs: recall@{k} of the true nearest, median best cost of the chosen pairs")
    for r in rows:
        print(f"{r['descriptor']:>36} {r['recall']:>7.3f} {r['median_cost']:>9.1f}")
    return rows


def index_speed(n: int, d: int = 32, k: int = 10) -> dict:
    """CPU seconds of the k-NN query of n points in d dimensions (Gaussian, spectrum decaying as i^-0.75) with
    scipy's cKDTree, faiss's exact flat index and faiss HNSW (candidates.HNSW_PARAMS), one thread; HNSW recall
    against the exact result and whether two HNSW builds agree."""
    import faiss
    from scipy.spatial import cKDTree

    from corr_core.alignment import candidates

    faiss.omp_set_num_threads(1)
    X = (np.random.default_rng(0).normal(size=(n, d)) * np.arange(1, d + 1) ** -0.75).astype(np.float32)
    out = {"n": n, "d": d}
    t = time.process_time()
    cKDTree(X).query(X, k=k + 1)
    out["kdtree_s"] = time.process_time() - t
    t = time.process_time()
    flat = faiss.IndexFlatL2(d)
    flat.add(X)
    exact = flat.search(X, k + 1)[1]
    out["flat_s"] = time.process_time() - t

    def hnsw():
        index = faiss.IndexHNSWFlat(d, candidates.HNSW_PARAMS["M"])
        index.hnsw.efConstruction = candidates.HNSW_PARAMS["efConstruction"]
        index.add(X)
        index.hnsw.efSearch = candidates.HNSW_PARAMS["efSearch"]
        return index.search(X, k + 1)[1]
    t = time.process_time()
    approx = hnsw()
    out["hnsw_s"] = time.process_time() - t
    out["hnsw_recall"] = float(np.mean([len(set(a) & set(b)) / (k + 1) for a, b in zip(exact, approx)]))
    out["hnsw_deterministic"] = bool(np.array_equal(approx, hnsw()))
    print(f"index, N={n} d={d} {k}-NN, CPU s: kd-tree {out['kdtree_s']:.1f}, faiss flat {out['flat_s']:.1f}, "
          f"faiss HNSW {out['hnsw_s']:.1f} (recall {out['hnsw_recall']:.4f}, "
          f"deterministic {out['hnsw_deterministic']})", flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="*", default=[100, 300, 1000])
    ap.add_argument("--set", dest="sets", action="append", default=[], help="extra --set for the pipeline runs")
    ap.add_argument("--compare-complete", action="store_true",
                    help="also run graph=complete through the same stages at each size (views/hog reused)")
    ap.add_argument("--synthetic", type=int, nargs="*", default=None,
                    help="candidate-graph pair/solve stages on synthesized features at these sizes")
    ap.add_argument("--evaluate-max", type=int, default=30000,
                    help="--synthetic: run the evaluate stage only up to this N (its ICM sweeps are Python loops)")
    ap.add_argument("--k", type=int, default=10, help="--synthetic: nearest shapes per shape")
    ap.add_argument("--n-random", type=int, default=2, help="--synthetic: random partners per shape")
    ap.add_argument("--descriptor-quality", type=int, default=None, metavar="N",
                    help="recall of the true nearest shapes for several descriptors on N generated chairs")
    ap.add_argument("--index-speed", type=int, nargs="*", default=None, metavar="N",
                    help="k-NN index CPU time (kd-tree, faiss flat, faiss HNSW) at these sizes")
    ap.add_argument("--n", type=int, default=None, help="complete-graph MRF memory check at this N (dense C)")
    ap.add_argument("--mrf-configs", nargs="*", default=["spectral:0", "lh:0", "spectral:10", "lh:10"],
                    help="solver:knn pairs for --n")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--work", default="/tmp/scale_bench")
    ap.add_argument("--json", default=None, help="write all numbers here")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    report: dict = {}
    if args.descriptor_quality:
        report["descriptor_quality"] = descriptor_quality(args.descriptor_quality, work)
    elif args.index_speed:
        report["index_speed"] = [index_speed(n) for n in args.index_speed]
    elif args.n:
        configs = [(c.split(":")[0], int(c.split(":")[1])) for c in args.mrf_configs]
        report["mrf_memory"] = bench_mrf_memory(args.n, configs, work)
    elif args.synthetic:
        rows = [bench_synthetic(n, work, args.k, args.n_random, n <= args.evaluate_max) for n in args.synthetic]
        report.update(synthetic=rows, exponents=print_synthetic(rows))
    else:
        rows = []
        for n in args.sizes:
            rows.append(bench_size(n, work, args.workers, keep=False, sets=args.sets))
            print(f"n={n}: done in {rows[-1]['wall']:.1f} s", flush=True)
            if args.compare_complete:
                rows.append(compare_complete(n, work, args.workers))
                print(f"n={n} complete graph: done in {rows[-1]['wall']:.1f} s", flush=True)
        timing = [r for r in rows if "graph=complete" not in r["sets"]]
        exps = growth_exponents(timing) if len(timing) > 1 else {}
        print_table(rows, exps)
        report.update(sizes=rows, exponents=exps)
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
