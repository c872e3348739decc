"""Where a dense map's CPU time goes: per pair and mode, the seconds of each part of ``dense_map``.

Each part is a function ``dense_map`` reaches, timed while the map is made (``PartTimer``: CPU seconds, a part's
time without the parts it calls, so the parts add up to the whole): the target's basis (``mesh_basis``), the
feature points (``init.extremities``), their distance features (``init.point_features``), the initial functional
maps (``init.map_from_points``, the probes of the automatic mode included), ZoomOut (``zoomout.zoomout``), the
point matching after it (``init._zoomout_and_match``), the upsampling to every vertex (``upsample_spectral``), each
refinement step (``refine.REFINE_STEPS``: extrinsic, spectral, deform) and the distortion that ranks the
hypotheses (``refine.map_distortion``); "other" is the rest. The template's basis, its extremities and its patch
geodesics are made before the timing (once per template; ``bench/correspondence.py`` counts the extremities in its
first pair). The maps are ``dense_map``'s, bit for bit (the wrappers only time).

With ``--profile N``: afterwards, a cProfile of one more map per mode (the first target), its top N functions by
own time (cProfile slows the map down; the table above is without it).

Run:  python bench/dense_cost.py [--data ../shared/data/hw3/scape] [--pairs 3] [--modes sparse,auto] [--profile 20]
      (--data: any folder in the course SCAPE layout, e.g. /tmp/scape_remeshed from bench/remesh_scape.py)
"""
from __future__ import annotations

import argparse
import contextlib
import functools
import os
import sys
import time
from collections import defaultdict

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import SCAPE as DEFAULT_DATA, one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()

import numpy as np  # noqa: E402

PARTS = ("target basis", "extremities", "point features", "initial fmaps", "ZoomOut", "matching", "upsample",
         "extrinsic", "spectral", "deform", "distortion", "other")


class PartTimer:
    """CPU seconds per label of the functions wrapped by ``wrap``, each without the time of wrapped functions it
    calls (a stack of the inner seconds), so the labels' seconds add up to the time spent in the outermost calls."""

    def __init__(self):
        self.seconds: dict = defaultdict(float)
        self._inner: list = []

    def wrap(self, label: str, fn):
        """``fn`` timed under ``label`` (same arguments, same result)."""
        @functools.wraps(fn)
        def timed(*args, **kwargs):
            t0 = time.process_time()
            self._inner.append(0.0)
            try:
                return fn(*args, **kwargs)
            finally:
                spent = time.process_time() - t0
                self.seconds[label] += spent - self._inner.pop()
                if self._inner:
                    self._inner[-1] += spent
        return timed


@contextlib.contextmanager
def timed_parts(timer: PartTimer):
    """Within the block, the functions of ``PARTS`` (but "target basis" and "other") are timed by ``timer`` where
    ``dense_map`` looks them up; restored on exit."""
    from corr_core.correspondence import dense
    from corr_core.correspondence.dense import init, refine, zoomout

    places = [(init, "extremities", "extremities"), (init, "point_features", "point features"),
              (init, "map_from_points", "initial fmaps"), (dense, "map_from_points", "initial fmaps"),
              (zoomout, "zoomout", "ZoomOut"), (init, "_zoomout_and_match", "matching"),
              (dense, "upsample_spectral", "upsample"), (refine, "map_distortion", "distortion")]
    saved = [(module, name, getattr(module, name)) for module, name, _ in places]
    saved_steps = dict(refine.REFINE_STEPS)
    try:
        for module, name, label in places:
            setattr(module, name, timer.wrap(label, getattr(module, name)))
        for name in ("extrinsic", "spectral", "deform"):
            refine.REFINE_STEPS[name] = timer.wrap(name, saved_steps[name])
        yield timer
    finally:
        for module, name, fn in saved:
            setattr(module, name, fn)
        refine.REFINE_STEPS.clear()
        refine.REFINE_STEPS.update(saved_steps)


def map_cost(template: tuple, V, F, mode: str, sparse: tuple | None, *, name: str = "target"
             ) -> tuple[np.ndarray, dict]:
    """One ``dense_map`` of the template (V_s (n_s,3), F_s, its basis S) to the mesh V (n,3), F (m,3) in ``mode``
    ("sparse": from ``sparse`` = (template ids (p,), target ids (p,)); "auto": no point), the target's basis made
    at S's k and sample count: (the map (n_s,) int, {part: CPU seconds} over ``PARTS``, "total" included)."""
    from corr_core.correspondence.dense import basis, dense_map

    V_s, F_s, S = template
    timer = PartTimer()
    t0 = time.process_time()
    T = basis.mesh_basis(V, F, k=S.evecs.shape[1], n_samples=len(S.samples), name=name)
    timer.seconds["target basis"] = time.process_time() - t0
    points = {} if mode == "auto" else {"landmarks_template": sparse[0], "landmarks_target": sparse[1]}
    with timed_parts(timer):
        p2p = dense_map(V_s, F_s, V, F, basis_template=S, basis_target=T, k=S.evecs.shape[1], **points)
    total = time.process_time() - t0
    seconds = {part: timer.seconds.get(part, 0.0) for part in PARTS[:-1]}
    seconds["other"] = total - sum(seconds.values())
    seconds["total"] = total
    return p2p, seconds


def print_table(costs: dict) -> None:
    """Mean CPU seconds per pair and share of the total, per part, one column per mode ({mode: [seconds dict]})."""
    modes = list(costs)
    print(f"{'part':16s}" + "".join(f"{m + ' s':>10s}{'share':>8s}" for m in modes))
    for part in PARTS + ("total",):
        row = f"{part:16s}"
        for m in modes:
            mean = float(np.mean([c[part] for c in costs[m]]))
            total = float(np.mean([c["total"] for c in costs[m]]))
            row += f"{mean:10.3f}{100 * mean / total:7.1f}%"
        print(row)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=DEFAULT_DATA, help="a folder in the course SCAPE layout")
    ap.add_argument("--pairs", type=int, default=3, help="the first N test meshes")
    ap.add_argument("--modes", default="sparse,auto")
    ap.add_argument("--profile", type=int, default=0, metavar="N", help="also a cProfile's top N of one map per mode")
    args = ap.parse_args(argv)
    modes = args.modes.split(",")
    if set(modes) - {"sparse", "auto"} or not modes:
        ap.error(f"--modes: sparse and/or auto, got {args.modes}")
    from bench.correspondence import checked_layout, pair_truth, read_template
    from corr_core.correspondence.dense import basis, init
    from corr_core.geometry.mesh_io import load_mesh

    found = checked_layout(ap, args.data, args.pairs)
    if found is None:
        return 2
    tpl, tests = found
    V_s, F_s, lm_ids, lm_names, sparse_names = read_template(args.data, tpl)
    S = basis.mesh_basis(V_s, F_s, k=100, name=tpl)
    S.sample_distances(300)                       # the template's work, once: patch geodesics and extremities
    init.cached_extremities(S)
    costs: dict = {m: [] for m in modes}
    targets = []
    for path in tests:
        name = os.path.splitext(os.path.basename(path))[0]
        V, F = load_mesh(path)
        given = pair_truth(args.data, name, lm_names, lm_ids, sparse_names, len(V_s), len(V))
        sparse = (given["sparse"][:, 0], given["sparse"][:, 1])
        targets.append((name, V, F, sparse))
        for m in modes:
            _, seconds = map_cost((V_s, F_s, S), V, F, m, sparse, name=name)
            costs[m].append(seconds)
            print(f"{name:10s} {m:6s} {seconds['total']:6.2f} s", flush=True)
    print(f"\n{len(tests)} pairs of {args.data}, CPU seconds per pair (one BLAS thread), template work excluded:")
    print_table(costs)
    if args.profile:
        import cProfile
        import pstats

        name, V, F, sparse = targets[0]
        for m in modes:
            profile = cProfile.Profile()
            profile.enable()
            map_cost((V_s, F_s, S), V, F, m, sparse, name=name)
            profile.disable()
            print(f"\ncProfile of one {m} map ({name}), top {args.profile} by own time:")
            pstats.Stats(profile).sort_stats("tottime").print_stats(args.profile)
    return 0


if __name__ == "__main__":
    sys.exit(main())
