"""Correspondence benchmark: seconds per mesh for each preprocessing step and per pair for each matching
method, with the share of the largest step. Times the corr_core functions the pipeline's stages call.

    python bench/correspondence_steps.py [--data ../shared/data/hw3/scape] [--meshes 3]

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

from corr_core.correspondence import matchers, mesh_features  # noqa: E402
from corr_core.correspondence.landmarks import read_landmarks, subset_positions  # noqa: E402
from corr_core.geometry.checks import check_correspondence_mesh  # noqa: E402
from corr_core.geometry.repair import load_repaired_mesh  # noqa: E402
from corr_core.geometry.primitives import surface_area  # noqa: E402

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


def load_checked(path: str) -> dict:
    """The mesh as the corr.mesh stage gives it: {"V", "F", "area"} (repaired, checked for intrinsic methods)."""
    V, F, _ = load_repaired_mesh(path, keep_largest_component=True)
    check_correspondence_mesh(V, F, name=os.path.basename(path))
    return {"V": V, "F": F, "area": surface_area(V, F)}


def prepare(path: str, landmark_ids: np.ndarray, pre: dict[str, list[float]]) -> tuple:
    """Per-mesh inputs of the matchers, each step timed into ``pre``."""
    m, t = timed(load_checked, path)
    pre["load+repair+check"].append(t)
    s, t = timed(mesh_features.spectral_features, m["V"], m["F"], landmark_ids)
    pre["eigenpairs+HKS/WKS"].append(t)
    g, t = timed(mesh_features.geodesic_features, m["V"], m["F"], landmark_ids)
    pre["geodesics"].append(t)
    f, t = timed(mesh_features.flattening_features, m["V"], m["F"], landmark_ids)
    pre["flatten+samples"].append(t)
    return m, s, g, f


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
    ids, _ = read_landmarks(data / "landmark_vids.txt")
    sparse = subset_positions(ids, read_landmarks(data / "sparse_landmark_vids.txt")[0])
    pre = {"load+repair+check": [], "eigenpairs+HKS/WKS": [], "geodesics": [], "flatten+samples": []}
    prepared = {path: prepare(path, ids, pre) for path in [template] + tests}
    n_vertices = len(prepared[template][0]["V"])
    print_shares(f"preprocessing, seconds per mesh ({len(prepared)} meshes, {n_vertices} vertices)", pre,
                 "preprocessing")
    per = {"descriptor+Hungarian": [], "geodesic MRF": [], "geodesic MRF+orientation": [], "Möbius voting": []}
    mT, sT, gT, fT = prepared[template]
    for path in tests:
        m, s, g, f = prepared[path]
        per["descriptor+Hungarian"].append(timed(matchers.match_descriptors, sT, s, sparse)[1])
        per["geodesic MRF"].append(timed(matchers.match_geodesic_mrf, gT, g, sparse)[1])
        per["geodesic MRF+orientation"].append(timed(matchers.match_geodesic_mrf, gT, g, sparse,
                                                     orientation_test=True)[1])
        per["Möbius voting"].append(timed(matchers.match_mobius, fT, f, mT, m, sparse, dense_points=0)[1])
    print_shares(f"matching, seconds per pair ({len(tests)} pairs, {len(ids)} + sparse {len(sparse)} landmarks)",
                 per, "matching time")


if __name__ == "__main__":
    main()
