"""The automatic dense map with and without ``refine.EARLY_DROP_MARGIN`` (a starting map surely beaten after the
first round of the patch ICP gets none of its other rounds), in one run: per target, both maps' CPU seconds, how
many starting maps were dropped after that round, and whether the two maps are the same bit for bit.

The two runs of a target alternate in order (without first on even targets, with first on odd ones), each with a
fresh target basis (no cache of the other run), one BLAS thread. "Without" is ``early_margin=inf``: every
starting map gets the whole first step, as before session 36.

Run:  python bench/early_drop.py [--data ../shared/data/hw3/scape] [--pairs 20]
      (--data: any folder in the course SCAPE layout, e.g. /tmp/scape_remeshed from bench/remesh_scape.py)
"""
from __future__ import annotations

import argparse
import functools
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import SCAPE as DEFAULT_DATA, one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()

import numpy as np  # noqa: E402


def one_map(S, V_s, F_s, V, F, name: str, early_margin: float) -> tuple[np.ndarray, float, int]:
    """The automatic map template -> (V, F) with ``early_margin``: (map (n_s,) int, CPU seconds, starting maps
    dropped after the first round)."""
    from corr_core.correspondence import dense
    from corr_core.correspondence.dense import basis, refine

    kept = []

    def refine_best(*args, **kwargs):
        best = refine.refine_best(*args, **kwargs, early_margin=early_margin)
        kept.append(best)
        return best

    T = basis.mesh_basis(V, F, k=S.evecs.shape[1], n_samples=len(S.samples), name=name)
    saved = dense.refine_best
    dense.refine_best = refine_best
    try:
        t0 = time.process_time()
        p2p = dense.dense_map(V_s, F_s, V, F, basis_template=S, basis_target=T, k=S.evecs.shape[1])
        seconds = time.process_time() - t0
    finally:
        dense.refine_best = saved
    best = kept[-1]
    early = sum(1 for i, s in enumerate(best.step_distortions) if best.dropped and best.dropped[i] and not s)
    return p2p, seconds, early


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=DEFAULT_DATA, help="a folder in the course SCAPE layout")
    ap.add_argument("--pairs", type=int, default=20, help="the first N test meshes")
    args = ap.parse_args(argv)
    from bench.correspondence import checked_layout, read_template
    from corr_core.correspondence.dense import basis, refine
    from corr_core.geometry.mesh_io import load_mesh

    found = checked_layout(ap, args.data, args.pairs)
    if found is None:
        return 2
    tpl, tests = found
    V_s, F_s, *_ = read_template(args.data, tpl)
    S = basis.mesh_basis(V_s, F_s, k=100, name=tpl)
    S.sample_distances(300)                       # the template's work, once: patch geodesics
    runs = {"without": float("inf"), "with": refine.EARLY_DROP_MARGIN}
    total = dict.fromkeys(runs, 0.0)
    same = dropped_targets = 0
    for n, path in enumerate(tests):
        name = os.path.splitext(os.path.basename(path))[0]
        V, F = load_mesh(path)
        order = list(runs) if n % 2 == 0 else list(runs)[::-1]
        out = {label: one_map(S, V_s, F_s, V, F, name, runs[label]) for label in order}
        for label in runs:
            total[label] += out[label][1]
        equal = np.array_equal(out["without"][0], out["with"][0])
        same += equal
        dropped_targets += out["with"][2] > 0
        print(f"{name:10s} without {out['without'][1]:5.2f} s, with {out['with'][1]:5.2f} s "
              f"(dropped after the first round: {out['with'][2]}), same map: {equal}", flush=True)
    print(f"\n{len(tests)} targets of {args.data}: {same} maps the same; a starting map dropped after the first round "
          f"on {dropped_targets}; CPU {total['without']:.1f} -> {total['with']:.1f} s "
          f"(ratio {total['with'] / total['without']:.3f}; EARLY_DROP_MARGIN {refine.EARLY_DROP_MARGIN})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
