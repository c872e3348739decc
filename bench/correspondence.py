"""Correspondence benchmark: seconds per mesh for each preprocessing step and per pair for each matching
method, with the share of the largest step.

    python bench/correspondence.py [--data ../shared/data/hw3/scape] [--meshes 3]

Without the course data it uses the generated humanoid (corr_core.generate).
"""
from __future__ import annotations

import argparse
import glob
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from shapecorr import correspondence as corr  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t0


def print_shares(title: str, timings: dict[str, list[float]], whole: str) -> None:
    """Mean seconds of each step, its share of the total, and the largest step."""
    means = {k: float(np.mean(v)) for k, v in timings.items()}
    total = sum(means.values())
    print(f"\n{title}")
    for k, v in means.items():
        print(f"  {k:<26} {v:8.4f} s   {v / total:6.1%}")
    largest = max(means, key=means.get)
    print(f"  largest: {largest} ({means[largest] / total:.0%} of {whole})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data" / "hw3" / "scape"))
    ap.add_argument("--meshes", type=int, default=3, help="number of test meshes to time")
    args = ap.parse_args()
    data = Path(args.data)
    if not (data / "meshes").is_dir():
        from corr_core.generate import write_humanoid_dataset
        data = Path(tempfile.mkdtemp()) / "humanoid"
        write_humanoid_dataset(data, n_poses=args.meshes, seed=0)
        print(f"course data not found; using a generated humanoid in {data}")
    template = sorted(glob.glob(str(data / "meshes" / "template" / "*.obj")))[0]
    tests = sorted(glob.glob(str(data / "meshes" / "test" / "*.obj")))[: args.meshes]
    lm, sparse = str(data / "landmark_vids.txt"), str(data / "sparse_landmark_vids.txt")
    pre = {"load+check": [], "eigenpairs+HKS/WKS": [], "geodesics": [], "flatten+samples": []}
    prepared = {}
    for path in [template] + tests:
        m, t = timed(corr.mesh, path)
        pre["load+check"].append(t)
        s, t = timed(corr.spectral, m, lm)
        pre["eigenpairs+HKS/WKS"].append(t)
        g, t = timed(corr.geodesics, m, lm)
        pre["geodesics"].append(t)
        f, t = timed(corr.flatten, m, path, lm)
        pre["flatten+samples"].append(t)
        prepared[path] = (m, s, g, f)
    n_vertices = len(prepared[template][0]["V"])
    print_shares(f"preprocessing, seconds per mesh ({len(prepared)} meshes, {n_vertices} vertices)", pre,
                 "preprocessing")
    per = {"descriptor+Hungarian": [], "geodesic MRF": [], "geodesic MRF+orientation": [], "Möbius voting": []}
    mT, sT, gT, fT = prepared[template]
    for path in tests:
        m, s, g, f = prepared[path]
        per["descriptor+Hungarian"].append(timed(corr.match_descriptor, sT, s, lm, sparse)[1])
        per["geodesic MRF"].append(timed(corr.match_mrf, gT, g, lm, sparse)[1])
        per["geodesic MRF+orientation"].append(timed(corr.match_mrf, gT, g, lm, sparse, orientation=True)[1])
        per["Möbius voting"].append(timed(corr.match_mobius, fT, f, mT, m, lm, sparse, dense_points=0)[1])
    print_shares(f"matching, seconds per pair ({len(tests)} pairs, all 20 + sparse 5 landmarks)", per, "matching time")


if __name__ == "__main__":
    main()
