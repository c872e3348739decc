"""How many triplet maps ``mobius.score_maps`` scores per block (its ``chunk``): time and identity of the scores.

Each block holds chunk x p x q complex distances; small blocks stay in the CPU caches, large ones stream through
memory several times (subtraction, modulus, scale, the mutual-nearest test). Random Möbius maps and samples (no
mesh, no course data): T triplet maps of 300 source and 300 target samples, metric "surface", as the
``corr.match_mobius`` stage scores the 600 triplet pairs of 5 sparse landmarks. Printed per chunk: best-of-3 wall
seconds, the ratio to the largest chunk, and whether the scores equal the largest chunk's bit for bit.

Run:  python bench/mobius_chunk.py [--maps 600] [--samples 300] [--chunks 256,64,32,16,8,4]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()

import numpy as np  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--maps", type=int, default=600)
    ap.add_argument("--samples", type=int, default=300)
    ap.add_argument("--chunks", default="256,64,32,16,8,4")
    args = ap.parse_args(argv)
    from corr_core.correspondence.mobius import score_maps

    rng = np.random.default_rng(0)
    maps = [rng.standard_normal((args.maps, 4)) + 1j * rng.standard_normal((args.maps, 4)) for _ in range(2)]
    Z = [rng.standard_normal(args.samples) + 1j * rng.standard_normal(args.samples) for _ in range(2)]
    lam = [rng.random(args.samples) + 0.5 for _ in range(2)]
    chunks = sorted((int(c) for c in args.chunks.split(",")), reverse=True)
    reference, first = None, None
    print(f"score_maps: {args.maps} maps, {args.samples} x {args.samples} samples, metric surface")
    for chunk in chunks:
        best = float("inf")
        for _ in range(3):
            t0 = time.perf_counter()
            scores = score_maps(*maps, *Z, K=0.5, metric="surface", lam_s=lam[0], lam_t=lam[1], K_scale=0.7,
                                chunk=chunk)
            best = min(best, time.perf_counter() - t0)
        if reference is None:
            reference, first = scores, best
        print(f"  chunk {chunk:>4}: {best:.3f} s  ratio {best / first:.2f}  same scores: "
              f"{np.array_equal(scores, reference)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
