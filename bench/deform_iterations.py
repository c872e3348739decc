"""How far the ARAP registration (``deform.refine_deform``) is from converged: its default against longer runs, on
generated data (never the course poses).

Per seed, ``write_humanoid_dataset(n_poses, seed, vary_bodies=...)`` with a decimated, vertex-shuffled copy of pose 1;
for every target the map from the 5 sparse landmarks (``map_from_points``, as dense_sparse makes it) is upsampled
and refined by "extrinsic+spectral", then by each variant of the last step: the default "deform" (3 iterations per
round, 10 rounds), "deform" then a second pass with 6 iterations per round, single passes with more
iterations or rounds, and a weaker pull toward the current images ("anchor W": ``anchor_weight`` W instead of 0.5,
alone or as a second pass). Printed per target: each variant's mean geodesic error / sqrt(area) at 500 template samples;
the summary: mean error per variant, targets lower than the default, CPU seconds of the variant.
Settings as ``bench/dense_hypotheses.py`` (k 60, 1000 samples, 150 patches).

Run:  python bench/deform_iterations.py [--seeds 10,11] [--poses 4] [--same-body] [--json OUT]
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

from bench.dense_hypotheses import SETTINGS, generated_targets, generated_template, seed_range  # noqa: E402

VARIANTS = {"deform (default)": [{}], "deform + deform(6 it)": [{}, {"iterations": 6}],
            "deform(6 it)": [{"iterations": 6}], "deform(10 it)": [{"iterations": 10}],
            "deform(6 it, 20 rounds)": [{"iterations": 6, "rounds": 20}],
            "anchor 0.3": [{"anchor_weight": 0.3}], "anchor 0.2": [{"anchor_weight": 0.2}],
            "anchor 0.1": [{"anchor_weight": 0.1}], "deform + anchor 0.2": [{}, {"anchor_weight": 0.2}],
            "deform + anchor 0.1": [{}, {"anchor_weight": 0.1}]}


def score(S, T, V_t, F_t, truth, sparse) -> dict:
    """{variant: {"mean_error", "seconds"}} of one target (module docstring)."""
    from corr_core.correspondence.dense import RefineStep, init, measures, refine, upsample_spectral
    from corr_core.correspondence.dense.basis import map_to_original
    from corr_core.geometry.geodesic import GeodesicSolver

    C, p2p = init.map_from_points(S, T, sparse, truth[sparse], k_init=SETTINGS["k_init"], k_end=SETTINGS["k"])
    start = refine.refine_map(S, T, upsample_spectral(S, T, C, p2p),
                              [RefineStep("extrinsic", {"n_patches": SETTINGS["n_patches"]}), "spectral"])
    maps, seconds = {}, {}
    for name, passes in VARIANTS.items():
        t0 = time.process_time()
        maps[name] = refine.refine_map(S, T, start, [RefineStep("deform", options) for options in passes])
        seconds[name] = time.process_time() - t0
    errors = measures.dense_errors(V_t, F_t, {n: map_to_original(S, T, m) for n, m in maps.items()}, truth,
                                   vertices=S.vids[S.samples[:SETTINGS["eval_vertices"]]],
                                   solver=GeodesicSolver(V_t, F_t))
    return {n: {"mean_error": float(errors[n].mean()), "seconds": seconds[n]} for n in VARIANTS}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="10,11")
    ap.add_argument("--poses", type=int, default=4)
    ap.add_argument("--same-body", action="store_true", help="poses of one body (as the default pipeline)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    from corr_core.correspondence.dense import basis
    from corr_core.correspondence.landmarks import read_landmarks

    work = tempfile.mkdtemp(prefix="deform_iterations_")
    results = []
    for seed in seed_range(args.seeds):
        root, V_s, S = generated_template(work, seed, args.poses, vary_bodies=not args.same_body)
        sparse, _ = read_landmarks(os.path.join(root, "sparse_landmark_vids.txt"), n_vertices=len(V_s))
        for name, V_t, F_t, truth in generated_targets(root, decimated=True):
            T = basis.mesh_basis(V_t, F_t, k=SETTINGS["k"], n_samples=SETTINGS["n_samples"])
            row = {"seed": seed, "mesh": name, "variants": score(S, T, V_t, F_t, truth, sparse)}
            results.append(row)
            print(f"seed {seed} {name} ({len(V_t)} v)  " + "  ".join(
                f"{n}: {v['mean_error']:.5f}" for n, v in row["variants"].items()), flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)
    base = np.array([r["variants"]["deform (default)"]["mean_error"] for r in results])
    print(f"\n{len(results)} targets ({'one body' if args.same_body else 'other bodies'}, seeds {args.seeds}); "
          f"per variant: mean error, targets lower than the default, CPU s of the deform passes per target")
    for n in VARIANTS:
        err = np.array([r["variants"][n]["mean_error"] for r in results])
        print(f"  {n:<26} {err.mean():.5f}  lower {int(np.sum(err < base))} of {len(err)}  "
              f"{np.mean([r['variants'][n]['seconds'] for r in results]):.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
