"""The settling step (``deform.refine_settle``) and its two numbers, swept on generated bodies (never the course).

Per seed, ``write_humanoid_dataset(n_poses, seed, vary_bodies=...)`` with a decimated, vertex-shuffled copy of
pose 1 (other connectivity); the truth (vertex i <-> i, or the generator's ground truth for the copy) is used only
to score. For every target the automatic map is made as the pipeline does (``init.automatic_hypotheses``, every
hypothesis refined with "extrinsic+spectral+deform", ``refine.refine_best``), then ``refine_settle`` runs from it
with each setting of ``--iterations`` x ``--stiffness``; printed: mean geodesic error / sqrt(area) at 500 template
samples (0 iterations: no settling), CPU seconds of the settling; the summary: mean error and seconds per setting.
Settings as ``bench/dense_hypotheses.py`` (k 60, 1000 samples, 150 patches).

Run:  python bench/settle_sweep.py [--seeds 10-11] [--poses 4] [--same-body] [--json OUT]
      (an existing --json file is resumed: its targets are not run again, and the summary covers all of them)
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

BEFORE_SETTLING = "extrinsic+spectral+deform"


def settle_rows(S, T, V_t, F_t, truth, iterations: list[int], stiffness: list[float]) -> dict:
    """{"iterations/stiffness": {"mean_error", "seconds"}} of one target (module docstring)."""
    from corr_core.correspondence.dense import init, measures, refine, upsample_spectral
    from corr_core.correspondence.dense.basis import map_to_original
    from corr_core.correspondence.dense.deform import refine_settle
    from corr_core.geometry.geodesic import GeodesicSolver

    starts = init.automatic_hypotheses(S, T, k_init=SETTINGS["k_init"], k_end=SETTINGS["k"])
    maps = [upsample_spectral(S, T, C, p2p) for C, p2p in starts]
    base = refine.refine_best(S, T, maps, BEFORE_SETTLING, {"extrinsic": {"n_patches": SETTINGS["n_patches"]}}).p2p
    solver = GeodesicSolver(V_t, F_t)
    vertices = S.vids[S.samples[:SETTINGS["eval_vertices"]]]

    def error(p2p):
        vertex_map = map_to_original(S, T, p2p)
        return float(measures.dense_errors(V_t, F_t, {"m": vertex_map}, truth, vertices=vertices,
                                           solver=solver)["m"].mean())

    rows = {"0": {"mean_error": error(base), "seconds": 0.0}}
    for it in iterations:
        for st in stiffness:
            t0 = time.process_time()
            settled = refine_settle(S, T, base, stiffness=st, iterations=it)
            rows[f"{it}/{st:g}"] = {"mean_error": error(settled), "seconds": time.process_time() - t0}
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="10-11")
    ap.add_argument("--poses", type=int, default=4)
    ap.add_argument("--same-body", action="store_true", help="every pose of the same person (near-isometric)")
    ap.add_argument("--iterations", default="3,6,10")
    ap.add_argument("--stiffness", default="0.02,0.03,0.05")
    ap.add_argument("--work", default=None, help="folder for the generated data (default: a temporary one)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    iterations = [int(x) for x in args.iterations.split(",")]
    stiffness = [float(x) for x in args.stiffness.split(",")]

    from corr_core.correspondence.dense import basis

    work = args.work or tempfile.mkdtemp(prefix="settle_sweep_")
    results = resumed_results(args.json, seed_range(args.seeds))   # resume: targets already in the file are kept
    done = {(r["seed"], r["mesh"]) for r in results}
    for seed in seed_range(args.seeds):
        root, _, S = generated_template(work, seed, args.poses, vary_bodies=not args.same_body)
        for name, V_t, F_t, truth in generated_targets(root, True):
            if (seed, name) in done:
                continue
            T = basis.mesh_basis(V_t, F_t, k=SETTINGS["k"], n_samples=SETTINGS["n_samples"])
            rows = settle_rows(S, T, V_t, F_t, truth, iterations, stiffness)
            results.append({"seed": seed, "mesh": name, "n_vertices": len(V_t), "settings": rows})
            print(f"seed {seed} {name} ({len(V_t)} v): " + "  ".join(
                f"{k} {r['mean_error']:.4f}" for k, r in rows.items()), flush=True)
            if args.json:
                with open(args.json, "w") as fh:
                    json.dump(results, fh, indent=1)
    print(f"\n{len(results)} targets ({'same body' if args.same_body else 'other bodies'}, seeds {args.seeds}); "
          "iterations/stiffness: mean error, CPU s of the settling per target")
    for key in results[0]["settings"]:
        errs = [r["settings"][key]["mean_error"] for r in results]
        secs = [r["settings"][key]["seconds"] for r in results]
        better = sum(e < r["settings"]["0"]["mean_error"] for e, r in zip(errs, results))
        print(f"  {key:>8}: {np.mean(errs):.5f}  ({np.mean(secs):.1f} s; lower than unsettled on {better} of "
              f"{len(results)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
