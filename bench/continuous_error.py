"""Time of ``corr_core.alignment.measures.continuous_error`` (the alignment metrics' error of continuous azimuths up
to the best global offset, on a grid of 36,000 offsets) against the loop over offsets it replaced, and per block
size of its offsets, on random azimuths of N shapes. Every variant must give the same means bit for bit (checked).

Run:  python bench/continuous_error.py [--shapes 24,98,1000,10000]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()

from corr_core.alignment.measures import continuous_error, offset_mean_errors, periodic_distance  # noqa: E402

OFFSETS = np.arange(0.0, 360.0, 0.01)     # continuous_error's default grid (resolution_deg=0.01)


def means_one_offset_at_a_time(diff: np.ndarray, period: np.ndarray) -> np.ndarray:
    """(n_offsets,) mean periodic error per offset, one offset at a time, stacked in blocks of 64 MB (the code
    before 2026-12-07)."""
    step = max(1, (64 << 20) // (8 * diff.size))
    return np.concatenate([np.stack([periodic_distance(diff - o, period) for o in OFFSETS[s:s + step]]).mean(axis=1)
                           for s in range(0, len(OFFSETS), step)])


def timed(fn, *args) -> tuple[float, np.ndarray]:
    t0 = time.perf_counter()
    out = fn(*args)
    return time.perf_counter() - t0, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shapes", default="24,98,1000,10000", help="comma-separated N (default: %(default)s)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    blocks = (1 << 14, 1 << 16, 1 << 18, 1 << 23)     # 1 << 23 values = 64 MB, the block size before 2026-12-07
    print("N       one offset at a time  " + "  ".join(f"blocks of {b:>8,}" for b in blocks) + "   continuous_error")
    for n in (int(x) for x in args.shapes.split(",")):
        diff = rng.random(n) * 360.0
        period = 360.0 / rng.integers(1, 4, n)
        base_s, base = timed(means_one_offset_at_a_time, diff, period)
        cells = []
        for b in blocks:
            s, means = timed(lambda: offset_mean_errors(diff, period, OFFSETS, block_values=b))
            if not np.array_equal(means, base):
                raise SystemExit(f"N={n}, blocks of {b}: the means differ from the loop's")
            cells.append(f"{s:8.3f} s ({s / base_s:4.2f})")
        whole_s, _ = timed(continuous_error, diff, np.zeros(n), 360.0 / period)
        print(f"{n:<7} {base_s:10.3f} s          " + "  ".join(f"{c:>18}" for c in cells) + f"   {whole_s:8.3f} s")
    print("(seconds; in brackets: over one offset at a time; every block size gave the loop's means bit for bit)")


if __name__ == "__main__":
    main()
