"""A second opinion for the automatic dense map, from its own points: its two choice rules compared.

On the course poses the automatic map is worse than the map from the 5 given points (0.010192 against 0.008986,
session 32), and the gap sits in the legs: the automatic start (the coarse probe's functional map, continued by
ZoomOut) leaves a thigh slid or twisted that the refinement only shrinks. The experiment here: take the template's
feature points (``init.cached_extremities``) and their images under the refined automatic map as if they were
given points, make the map from them as the sparse mode does (``refine.own_points_start``), refine it with them
held, and keep it where it is less distorted than the automatic map. Two rules are scored on
the same maps: "last" (``refine.map_distortion`` of the two final maps) and "score" (``refine.refinement_score``
over the plan's steps against the kept hypothesis's score). No ground truth is used by either rule. The library
has rule "last" as ``refine.second_opinion`` (``dense_map(second_opinion=True)``, off by default); this bench
makes the map step by step as it does, to score both rules on the same maps.

Data: generated other bodies (``bench/dense_hypotheses.py``'s targets: 6 poses of other people and a decimated,
vertex-shuffled copy of pose 1 per seed, its settings), never the course poses. Printed per target: the mean
error (geodesic / sqrt(area), ``SETTINGS["eval_vertices"]`` template vertices) of the automatic map and of the
second opinion, their landmark accuracy, both rules' distortions, the CPU seconds of each; then per rule the mean
error of the maps it keeps, on how many targets it is lower / higher than the automatic map's, and the flips
(landmark accuracy < 0.5).

Run:  python bench/second_opinion.py --seeds 5-9 [--refine extrinsic+deform] [--json OUT] [--work DIR]
      (--json: one row per target, written as it goes; a run again with the same file skips the targets in it)
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()

from bench.dense_hypotheses import SETTINGS, generated_targets, generated_template, resumed_results, seed_range  # noqa: E402
from corr_core.correspondence.dense import basis, init, measures, refine, upsample_spectral  # noqa: E402
from corr_core.correspondence.dense.transfer import transfer_landmarks  # noqa: E402
from corr_core.correspondence.landmarks import read_landmarks  # noqa: E402
from corr_core.geometry.geodesic import GeodesicSolver  # noqa: E402

RULES = ("last", "score")


def second_opinion(S, T, best: refine.BestMap, plan) -> tuple[np.ndarray, list[float]]:
    """The map of ``refine.own_points_start(best.p2p)``, refined by ``plan`` with its points held as
    ``refine.second_opinion`` refines it, one step at a time: (p2p (n_s,) int local, map_distortion after each
    step); (best.p2p, [inf]) when there are not 3 distinct points (the library then keeps ``best``)."""
    start = refine.own_points_start(S, T, best.p2p, k_init=SETTINGS["k_init"], k_end=SETTINGS["k"])
    if start is None:
        return np.asarray(best.p2p), [float("inf")]
    other, points = start
    steps = []
    for step in plan:
        other = step.run(S, T, other, points)
        steps.append(refine.map_distortion(S, T, other))
    return other, steps


def one_target(S, T, V_t, F_t, truth, landmarks, plan) -> dict:
    """The automatic map as ``dense_map`` makes it, its second opinion, and both scored (module docstring)."""
    t0 = time.process_time()
    starts = init.automatic_hypotheses(S, T, None, k_init=SETTINGS["k_init"], k_end=SETTINGS["k"])
    best = refine.refine_best(S, T, [upsample_spectral(S, T, C, p) for C, p in starts], plan)
    t_auto = time.process_time() - t0
    t0 = time.process_time()
    other, steps = second_opinion(S, T, best, plan)
    t_second = time.process_time() - t0
    maps = {"auto": basis.map_to_original(S, T, best.p2p), "second": basis.map_to_original(S, T, other)}
    solver = GeodesicSolver(V_t, F_t)
    errors = measures.dense_errors(V_t, F_t, maps, truth, vertices=S.vids[S.samples[:SETTINGS["eval_vertices"]]],
                                   solver=solver)
    row = {"n": len(V_t), "seconds_auto": t_auto, "seconds_second": t_second,
           "score_auto": best.scores[best.index] if best.scores else best.distortions[best.index],
           "score_second": refine.refinement_score(steps),
           "last_auto": refine.map_distortion(S, T, best.p2p), "last_second": steps[-1]}
    for name, m in maps.items():
        _, nearest = measures.landmark_errors(V_t, F_t, transfer_landmarks(m, landmarks), truth[landmarks],
                                              solver=solver)
        row[f"error_{name}"] = float(errors[name].mean())
        row[f"accuracy_{name}"] = measures.landmark_accuracy(nearest)
    return row


def kept(row: dict, rule: str, what: str) -> float:
    """``what`` ("error" or "accuracy") of the map ``rule`` keeps for one target's row."""
    return row[f"{what}_second"] if row[f"{rule}_second"] < row[f"{rule}_auto"] else row[f"{what}_auto"]


def summary_lines(rows: list[dict]) -> list[str]:
    auto = np.array([r["error_auto"] for r in rows])
    out = [f"{len(rows)} targets: automatic map mean error {auto.mean():.5f}, flipped "
           f"{sum(r['accuracy_auto'] < 0.5 for r in rows)}; CPU s per target: automatic "
           f"{np.mean([r['seconds_auto'] for r in rows]):.2f}, second opinion "
           f"{np.mean([r['seconds_second'] for r in rows]):.2f}"]
    for rule in RULES:
        chosen = np.array([kept(r, rule, "error") for r in rows])
        flips = sum(kept(r, rule, "accuracy") < 0.5 for r in rows)
        out.append(f"rule {rule!r}: mean error {chosen.mean():.5f}, lower on {int((chosen < auto).sum())}, higher on "
                   f"{int((chosen > auto).sum())}, largest rise {max(0.0, float((chosen - auto).max())):.5f}, "
                   f"flipped {flips}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="5-9", help='generated seeds, "5-9" or "5,7" (default: %(default)s)')
    ap.add_argument("--refine", default=refine.DEFAULT_REFINE, help="refinement plan (default: %(default)s)")
    ap.add_argument("--json", default=None, help="per-target rows, written as they come (resumable)")
    ap.add_argument("--work", default=None, help="folder for the generated datasets (default: a temporary one)")
    args = ap.parse_args(argv)
    seeds = seed_range(args.seeds)
    work = args.work or tempfile.mkdtemp(prefix="second_opinion-")
    plan = refine.refine_plan(args.refine, {"extrinsic": {"n_patches": SETTINGS["n_patches"]}})
    rows = resumed_results(args.json, seeds)
    done = {(r["seed"], r["mesh"]) for r in rows}
    for seed in seeds:
        root, V_s, S = generated_template(work, seed, 6, decimated=True)
        landmarks, _ = read_landmarks(os.path.join(root, "landmark_vids.txt"), n_vertices=len(V_s))
        for name, V_t, F_t, truth in generated_targets(root, True):
            if (seed, name) in done:
                continue
            T = basis.mesh_basis(V_t, F_t, k=SETTINGS["k"], n_samples=SETTINGS["n_samples"])
            row = {"seed": seed, "mesh": name, **one_target(S, T, V_t, F_t, truth, landmarks, plan)}
            rows.append(row)
            if args.json:
                with open(args.json, "w") as fh:
                    json.dump(rows, fh, indent=1)
            print(f"seed {seed} {name:<12} automatic {row['error_auto']:.5f} (acc {row['accuracy_auto']:.2f})  "
                  f"second {row['error_second']:.5f} (acc {row['accuracy_second']:.2f})  last "
                  f"{row['last_auto']:.4f}/{row['last_second']:.4f}  score {row['score_auto']:.4f}/"
                  f"{row['score_second']:.4f}  CPU {row['seconds_auto']:.1f}+{row['seconds_second']:.1f} s", flush=True)
    print("\n".join(summary_lines([r for r in rows if r["seed"] in seeds])))
    return 0


if __name__ == "__main__":
    sys.exit(main())
