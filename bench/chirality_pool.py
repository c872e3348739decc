"""The chirality pool of the automatic initialisation (``init.CHIRALITY_POOL``), measured on generated bodies.

``init.rank_candidates`` keeps in its pool the candidate maps whose chirality agreement is above
``CHIRALITY_POOL`` (2/3) of the best candidate's; the pool must hold the right map (and the 180-degree turn,
which chirality cannot tell from it) and leave out twists (a map right on part of the body and mirrored
elsewhere: only the hands or only the feet swapped). Per seed, ``write_humanoid_dataset(n_poses, seed,
vary_bodies=True)`` with a decimated copy of pose 1 (the truth, used only to classify); for every target every
candidate of ``init.automatic_hypotheses`` (its probe map at the template samples) is classified by the fraction
of samples mapped within 0.1 sqrt(area) of their true image: right (>= 0.7), part right (a twist; 0.2 to 0.7),
wrong (< 0.2: the turn, a mirror). Printed per target: each candidate's class and chirality / the best's; the
summary: the range of that ratio per class, i.e. the room the pool threshold has.

Run:  python bench/chirality_pool.py [--seeds 10-14] [--poses 4]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()

import numpy as np  # noqa: E402

from bench.dense_hypotheses import SETTINGS, generated_targets, generated_template, seed_range  # noqa: E402

RIGHT, PART = 0.7, 0.2       # fraction of samples within 0.1 sqrt(area) of the truth: right / part right (twist)


def classify(fraction: float) -> str:
    """"right", "twist" or "wrong" from the fraction of samples mapped near their true image."""
    return "right" if fraction >= RIGHT else "twist" if fraction >= PART else "wrong"


def candidate_rows(S, T, truth_original: np.ndarray) -> list[dict]:
    """[{"class", "ratio": chirality / best chirality, "near": fraction}] of every candidate of one target."""
    from corr_core.correspondence.dense import init

    _, info = init.automatic_hypotheses(S, T, n=1, k_init=SETTINGS["k_init"], k_end=SETTINGS["k"],
                                        return_info=True)
    best = max(c.chirality for c in info["candidates"])
    rows = []
    for c in info["candidates"]:
        p2p = c.p2p                                              # target vertex of each template sample (local)
        samples = S.samples[:len(p2p)]
        true_images = T.to_local(truth_original[S.vids[samples]], what="true image")
        gap = np.linalg.norm(T.V[p2p] - T.V[true_images], axis=1) / T.scale
        near = float(np.mean(gap < 0.1))
        rows.append({"class": classify(near), "ratio": float(c.chirality / best) if best > 0 else float("nan"),
                     "near": near})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="10-14")
    ap.add_argument("--poses", type=int, default=4)
    ap.add_argument("--work", default=None, help="folder for the generated data (default: a temporary one)")
    args = ap.parse_args(argv)

    from corr_core.correspondence.dense import basis
    from corr_core.correspondence.dense.init import CHIRALITY_POOL

    work = args.work or tempfile.mkdtemp(prefix="chirality_pool_")
    by_class: dict[str, list[float]] = {"right": [], "twist": [], "wrong": []}
    for seed in seed_range(args.seeds):
        root, _, S = generated_template(work, seed, args.poses, patch_geodesics=False)
        for name, V_t, F_t, truth in generated_targets(root, True):
            T = basis.mesh_basis(V_t, F_t, k=SETTINGS["k"], n_samples=SETTINGS["n_samples"])
            rows = candidate_rows(S, T, truth)
            for r in rows:
                by_class[r["class"]].append(r["ratio"])
            print(f"seed {seed} {name} ({len(V_t)} v): " + "  ".join(
                f"{r['class']} {r['ratio']:.2f} (near {r['near']:.2f})" for r in rows), flush=True)
    print(f"\nchirality agreement / the best candidate's, per class (pool threshold now {CHIRALITY_POOL:.3f}):")
    for cls, ratios in by_class.items():
        if ratios:
            print(f"  {cls:>5}: {len(ratios)} candidates, {min(ratios):.3f} to {max(ratios):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
