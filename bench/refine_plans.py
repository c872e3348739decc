"""Refinement plans compared on generated bodies of other people (never the course poses): the data behind
``refine.DEFAULT_REFINE``.

Per seed, ``write_humanoid_dataset(n_poses, seed, vary_bodies=True)`` (each pose another person) with a decimated,
vertex-shuffled copy of pose 1 (other connectivity); the truth (vertex i <-> i, or the generator's ground truth
for the copy) is used only to score. For every target the map from the sparse landmarks (``map_from_points``, as
dense_sparse makes it: no hypothesis to choose, so the plans are compared on the same start) is upsampled and
refined by each plan; steps a plan shares with an earlier one at its start are run once (their CPU seconds count
for every plan that uses them). Printed per target: each plan's mean geodesic error / sqrt(area) at 500 template
samples. The summary, per plan: mean and median error, targets lower / higher than the first plan, targets where
its ``map_distortion`` is lower than the first plan's, CPU seconds per target of its refinement.
Settings as ``bench/dense_hypotheses.py`` (k 60, 1000 samples, 150 patches: the bodies and default pipelines').

A plan written with the suffix ":points" (e.g. "extrinsic+spectral+deform:points") is refined with the sparse points
held: every step keeps them and the registration is constrained by them (``refine.refine_map(points=)``, as
``dense_map`` refines a map from given points).

Run:  python bench/refine_plans.py [--seeds 10-13] [--poses 6]
          [--plans extrinsic+spectral+deform,extrinsic+deform] [--json OUT]
      (an existing --json file is resumed: targets already in it are not run again)
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()

import numpy as np  # noqa: E402

from bench.dense_hypotheses import (SETTINGS, generated_targets, generated_template, resumed_results,  # noqa: E402
                                   seed_range)

PLANS = ("extrinsic+spectral+deform", "extrinsic+deform")
HELD = ":points"        # a plan written with this suffix refines with the sparse points held (refine_map(points=))


def refine_plans(S, T, start: np.ndarray, plans: list[str], points=None) -> dict[str, tuple[np.ndarray, float]]:
    """{plan: (refined (n_s,) int map, CPU s)}: each plan's steps run from ``start``, a prefix another plan already
    ran reused (its seconds counted again); a plan ending in ``HELD`` gets ``points`` (template, target local ids)
    as the given points every step keeps (``refine.refine_map(points=)``)."""
    from corr_core.correspondence.dense import refine

    done: dict[tuple, tuple[np.ndarray, float]] = {(False,): (start, 0.0), (True,): (start, 0.0)}
    out = {}
    for plan in plans:
        held = plan.endswith(HELD)
        steps = plan.removesuffix(HELD).split("+")
        cut = max(i for i in range(len(steps) + 1) if (held, *steps[:i]) in done)
        p2p, seconds = done[(held, *steps[:cut])]
        for i in range(cut, len(steps)):
            t0 = time.process_time()
            p2p = refine.refine_map(S, T, p2p, steps[i], {"extrinsic": {"n_patches": SETTINGS["n_patches"]}},
                                    points=points if held else None)
            seconds += time.process_time() - t0
            done[(held, *steps[:i + 1])] = (p2p, seconds)
        out[plan] = (p2p, seconds)
    return out


def score(S, T, V_t, F_t, truth, sparse, plans: list[str]) -> dict:
    """{plan: {"mean_error", "distortion", "seconds"}} of one target (module docstring)."""
    from corr_core.correspondence.dense import init, measures, refine, upsample_spectral
    from corr_core.correspondence.dense.basis import map_to_original
    from corr_core.geometry.geodesic import GeodesicSolver

    C, p2p = init.map_from_points(S, T, sparse, truth[sparse], k_init=SETTINGS["k_init"], k_end=SETTINGS["k"])
    points = (S.to_local(sparse), T.to_local(truth[sparse]))
    refined = refine_plans(S, T, upsample_spectral(S, T, C, p2p), plans, points)
    errors = measures.dense_errors(V_t, F_t, {p: map_to_original(S, T, m) for p, (m, _) in refined.items()}, truth,
                                   vertices=S.vids[S.samples[:SETTINGS["eval_vertices"]]],
                                   solver=GeodesicSolver(V_t, F_t))
    return {p: {"mean_error": float(errors[p].mean()), "distortion": refine.map_distortion(S, T, m),
                "seconds": seconds} for p, (m, seconds) in refined.items()}


def summary(results: list[dict], plans: list[str]) -> None:
    base = np.array([r["plans"][plans[0]]["mean_error"] for r in results])
    base_distortion = np.array([r["plans"][plans[0]]["distortion"] for r in results])
    print(f"\n{len(results)} targets; per plan: mean / median error, targets lower / higher than {plans[0]}, "
          f"targets with a lower distortion, CPU s per target")
    for p in plans:
        err = np.array([r["plans"][p]["mean_error"] for r in results])
        dist = np.array([r["plans"][p]["distortion"] for r in results])
        print(f"  {p:<32} {err.mean():.5f} {np.median(err):.5f}  lower {np.sum(err < base)}, higher "
              f"{np.sum(err > base)}  distortion lower {np.sum(dist < base_distortion)}  "
              f"{np.mean([r['plans'][p]['seconds'] for r in results]):.2f} s")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="10-13")
    ap.add_argument("--poses", type=int, default=6)
    ap.add_argument("--plans", default=",".join(PLANS), help="comma-separated plans; the first is the reference")
    ap.add_argument("--work", default=None, help="folder for the generated data (default: a temporary one)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    from corr_core.correspondence.dense import basis, refine_plan
    from corr_core.correspondence.landmarks import read_landmarks

    plans = [p.strip() for p in args.plans.split(",") if p.strip()]
    for p in plans:
        refine_plan(p.removesuffix(HELD))                  # a misspelt step fails before any work
    seeds = seed_range(args.seeds)
    work = args.work or tempfile.mkdtemp(prefix="refine_plans_")
    results = [r for r in resumed_results(args.json, seeds) if set(plans) <= set(r["plans"])]
    done = {(r["seed"], r["mesh"]) for r in results}
    for seed in seeds:
        root, V_s, S = generated_template(work, seed, args.poses)
        sparse, _ = read_landmarks(os.path.join(root, "sparse_landmark_vids.txt"), n_vertices=len(V_s))
        for name, V_t, F_t, truth in generated_targets(root, decimated=True):
            if (seed, name) in done:
                continue
            T = basis.mesh_basis(V_t, F_t, k=SETTINGS["k"], n_samples=SETTINGS["n_samples"])
            row = {"seed": seed, "mesh": name, "plans": score(S, T, V_t, F_t, truth, sparse, plans)}
            results.append(row)
            print(f"seed {seed} {name} ({len(V_t)} v)  " + "  ".join(
                f"{p}: {row['plans'][p]['mean_error']:.5f}" for p in plans), flush=True)
            if args.json:
                with open(args.json, "w") as fh:
                    json.dump(results, fh, indent=1)
    summary(results, plans)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
