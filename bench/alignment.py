"""Benchmark of the joint-alignment stages (run: python bench/alignment.py [--quick]).

Prints, all measured in this run (no assertions):
1. pairwise stage (with the default BLAS threads, then again in a subprocess with 1 BLAS thread):
   ``pair_costs`` (real DFT over views + one real GEMM per frequency) on N=100 shapes, V=16 views,
   D=8100 random float32, against ``pair_costs_naive`` (loop over pairs and thetas; timed on the first rows
   and scaled linearly in the number of pairs, which is exact for that loop) and against a Gram-matrix
   implementation (one float32 GEMM of all views); achieved GFLOP/s of each as a fraction of this machine's
   float32 GEMM rate measured on a (NV x D) x (D x NV) matmul, plus the rate of the GEMM shape pair_costs uses.
   On an oversubscribed machine multi-threaded OpenBLAS is very slow on pair_costs' small-output GEMMs; the
   1-thread run is the regime of dask workers.
2. MRF stage: CirculantPairwise vs DensePairwise matvec and one ``solve_lh`` on N=100, V=16.
3. bench/hog_render.py's bench_hog() and bench_render(), if that file exists.
"""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from corr_core.alignment.circulant import CirculantPairwise, dense_pairwise  # noqa: E402
from corr_core.alignment.pair_costs import auto_sigma, pair_costs, pair_costs_flops, pair_costs_naive  # noqa: E402
from corr_core.alignment.solvers import uniform_unary  # noqa: E402
from corr_core.mrf import solve_lh  # noqa: E402


def best_time(fn, repeat=3):
    """Minimum wall time of ``repeat`` calls (seconds) and the last result."""
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def pair_costs_gram(F: np.ndarray) -> np.ndarray:
    """Alternative fast path: Gram matrix of all N*V views (one float32 GEMM), then sum its circulant
    diagonals: (N, N, V)."""
    N, V, D = F.shape
    X = F.reshape(N * V, D)
    G = (X @ X.T).reshape(N, V, N, V)
    v = np.arange(V)
    cross = G[:, v[None, :], :, (v[None, :] + v[:, None]) % V].sum(axis=1)  # (V_theta, N, N)
    sq = np.einsum("ivd,ivd->i", F, F)
    return sq[:, None, None] + sq[None, :, None] - 2.0 * cross.transpose(1, 2, 0)


def bench_pairwise(N=100, V=16, D=8100, naive_rows=2, repeat=3):
    rng = np.random.default_rng(0)
    F = rng.random((N, V, D), dtype=np.float32)

    K = V // 2 + 1
    A = rng.random((N * V, D), dtype=np.float32)
    B = A.copy()
    t_sgemm, _ = best_time(lambda: A @ B.T, repeat)
    sgemm_rate = 2.0 * (N * V) ** 2 * D / t_sgemm / 1e9
    X = rng.random((N, 2 * D), dtype=np.float32)
    Y = rng.random((2 * N, 2 * D), dtype=np.float32)
    t_small, _ = best_time(lambda: [X @ Y.T for _ in range(K)], repeat)
    small_rate = K * 2.0 * N * 2 * N * 2 * D / t_small / 1e9

    t_fast, C = best_time(lambda: pair_costs(F), repeat)
    t_gram, C_gram = best_time(lambda: pair_costs_gram(F), repeat)
    t_rows, C_rows = best_time(lambda: pair_costs_naive(F[:naive_rows], F), 1)
    t_naive = t_rows * N / naive_rows
    err = float(np.abs(C[:naive_rows] - C_rows).max() / np.abs(C_rows).max())
    err_gram = float(np.abs(C - C_gram).max() / np.abs(C_gram).max())

    fft_flops = pair_costs_flops(N, N, V, D)
    gram_flops = 1.0 * (N * V) ** 2 * D  # X @ X.T: numpy calls syrk, which computes one triangle
    fft_rate, gram_rate = fft_flops / t_fast / 1e9, gram_flops / t_gram / 1e9
    print(f"[pairwise] N={N} V={V} D={D} float32, BLAS threads: {blas_threads()}")
    print(f"  machine float32 GEMM rate: {N*V}x{D}x{N*V}: {sgemm_rate:.1f} GFLOP/s ({t_sgemm*1e3:.0f} ms); "
          f"the shape pair_costs uses, {K}x({N}x{2*D}x{2*N}): {small_rate:.1f} GFLOP/s ({t_small*1e3:.0f} ms)")
    print(f"  pair_costs (real DFT + {K} real GEMMs): {t_fast*1e3:.0f} ms, {fft_flops/1e9:.2f} GFLOP -> "
          f"{fft_rate:.1f} GFLOP/s = {fft_rate/sgemm_rate:.0%} of the large-GEMM rate")
    print(f"  Gram-matrix variant (one GEMM):  {t_gram*1e3:.0f} ms, {gram_flops/1e9:.2f} GFLOP -> "
          f"{gram_rate:.1f} GFLOP/s = {gram_rate/sgemm_rate:.0%} of the large-GEMM rate (syrk: one triangle "
          f"counted); Gram/pair_costs time ratio {t_gram/t_fast:.2f}; max rel. diff {err_gram:.1e}")
    print(f"  pair_costs_naive: {t_rows:.2f} s for {naive_rows}x{N} pairs -> {t_naive:.1f} s for {N}x{N} "
          f"(linear in pairs); naive/pair_costs time ratio {t_naive/t_fast:.0f}x; max rel. diff {err:.1e}")
    return dict(t_fast=t_fast, t_gram=t_gram, t_naive=t_naive, sgemm_rate=sgemm_rate, small_rate=small_rate)


def blas_threads() -> str:
    return os.environ.get("OPENBLAS_NUM_THREADS", "default")


def bench_pairwise_single_thread(N: int, repeat: int) -> None:
    """Run bench_pairwise in a subprocess with 1 BLAS thread (the setting dask's nanny gives its workers)."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    code = (f"import sys; sys.path.insert(0, {str(ROOT / 'bench')!r}); import alignment; "
            f"alignment.bench_pairwise(N={N}, repeat={repeat})")
    subprocess.run([sys.executable, "-c", code], env=env, check=False)


def bench_mrf(N=100, V=16, repeat=3):
    rng = np.random.default_rng(1)
    F = rng.random((N, V, 64), dtype=np.float32)
    C = pair_costs(F)
    sigma = auto_sigma(C)
    circ, dense = CirculantPairwise(C, sigma), dense_pairwise(C, sigma)
    X = rng.random((N, V))
    t_c, _ = best_time(lambda: [circ.matvec(X) for _ in range(20)], repeat)
    t_d, _ = best_time(lambda: [dense.matvec(X) for _ in range(20)], repeat)
    U = uniform_unary(N, V, seed=0)
    t_lh, res = best_time(lambda: solve_lh(circ, U, compute_bound=False), repeat)
    t_lhd, _ = best_time(lambda: solve_lh(dense, U, compute_bound=False), repeat)
    t_b, _ = best_time(lambda: solve_lh(circ, U), 1)
    print(f"[mrf] N={N} V={V}")
    print(f"  matvec: circulant {t_c/20*1e6:.0f} us, dense ({N*V}x{N*V}) {t_d/20*1e6:.0f} us -> ratio {t_d/t_c:.1f}x")
    print(f"  solve_lh (no bound): circulant {t_lh*1e3:.0f} ms, dense {t_lhd*1e3:.0f} ms; with spectral bound "
          f"{t_b*1e3:.0f} ms; {res.iterations} relaxation iterations, {res.climb_moves} climbing moves")


def bench_hog_render():
    path = ROOT / "bench" / "hog_render.py"
    if not path.exists():
        print("[hog/render] bench/hog_render.py not found; skipped")
        return
    try:
        spec = importlib.util.spec_from_file_location("bench_hog_render", path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    except Exception as exc:  # another worker's file: report, do not crash this benchmark
        print(f"[hog/render] could not import bench/hog_render.py: {type(exc).__name__}: {exc}")
        return
    for name in ("bench_hog", "bench_render"):
        fn = getattr(mod, name, None)
        if fn is None:
            print(f"[hog/render] {name} not defined in bench/hog_render.py")
            continue
        try:
            print(f"[{name}] {fn()}")
        except Exception as exc:
            print(f"[{name}] failed: {type(exc).__name__}: {exc}")


if __name__ == "__main__":
    quick = "--quick" in sys.argv
    N, repeat = (40, 2) if quick else (100, 3)
    bench_pairwise(N=N, repeat=repeat)
    if blas_threads() != "1":
        bench_pairwise_single_thread(N, repeat)
    bench_mrf()
    bench_hog_render()
