"""The ZoomOut step of the dense map's starting maps (``init.ZOOMOUT_STEP``): error and cost per step value.

For every target, each mode's starting map is made with each ``--steps`` value (the growth of the basis per
ZoomOut iteration, from ``k_init`` to ``k``: ``init.map_from_points(step=)`` for ``sparse``, the 5 sparse landmarks
given on both meshes; ``init.automatic_hypotheses(step=)`` for ``auto``, the final ZoomOut of every hypothesis),
then upsampled and refined as ``dense_map`` does (``refine.refine_best`` with the default plan). Printed per target
and step: mean geodesic error / sqrt(area) of the map at the template's first ``eval_vertices`` samples, "F" when
flipped (landmark accuracy < 0.5), CPU seconds of the map (initialisation + refinement). The summary, per mode and
step: mean and median error, targets lower / higher than at the first step listed, flips, mean CPU seconds.

Data: generated bodies of other people (``--seeds``: ``write_humanoid_dataset(vary_bodies=True)``, ``--poses``
poses and a decimated, vertex-shuffled copy of pose 1 per seed; the truth only scores), at the settings of the
default and bodies pipelines (k 60, 1,000 samples, k_init 30, 150 patches) or with ``--course-settings`` at the
code's defaults (k 100, 2,000 samples, k_init 40, 300 patches: pipelines/scape.yaml's, where the automatic mode's
final ZoomOut runs from the probes' k 60 to 100; at k 60 it has no iteration left). ``--data DIR`` instead runs
template -> test meshes of a folder in the course SCAPE layout (e.g. ``/tmp/scape_remeshed`` from
``bench/remesh_scape.py``; ground truth and landmarks as ``bench/correspondence.py`` reads them), code defaults.

With ``--compare BASE OTHER`` (no run): two ``--json`` results of one step on the same targets (e.g. 300 and 150
patches) side by side per mode: mean and median error of each, the targets OTHER is lower / higher on, its largest
rise, flips, CPU seconds per map and their ratio OTHER / BASE.

Run:  python bench/zoomout_steps.py [--seeds 10-11] [--poses 4] [--course-settings] [--data DIR --pairs N]
                                    [--steps 2,3,4,6] [--modes sparse,auto] [--n-patches N] [--json OUT]
      python bench/zoomout_steps.py --compare BASE.json OTHER.json
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()

import numpy as np  # noqa: E402

CODE_SETTINGS = {"k": 100, "n_samples": 2000, "k_init": 40, "n_patches": 300, "eval_vertices": 2000}


def map_with_step(S, T, mode: str, step: int, settings: dict, sparse: tuple) -> np.ndarray:
    """The dense map (original ids) of one mode with ZoomOut step ``step``, made and refined as ``dense_map``."""
    from corr_core.correspondence.dense import init, refine
    from corr_core.correspondence.dense.basis import map_to_original

    if mode == "sparse":
        starts = [init.map_from_points(S, T, sparse[0], sparse[1], k_init=settings["k_init"], k_end=settings["k"],
                                       step=step)]
    else:
        starts = init.automatic_hypotheses(S, T, None, k_init=settings["k_init"], k_end=settings["k"], step=step)
    maps = [refine.upsample_spectral(S, T, C, p2p) for C, p2p in starts]
    plan = refine.refine_plan(refine.DEFAULT_REFINE, {"extrinsic": {"n_patches": settings["n_patches"]}})
    return map_to_original(S, T, refine.refine_best(S, T, maps, plan).p2p)


def scape_targets(data: str, template: str, tests: list[str], settings: dict):
    """Yield (template basis, template landmark ids (L,), name, V, F, truth (n_template,) int, the target's
    landmark ids (L,), sparse: (template ids (5,), target ids (5,))) for every test mesh path of ``tests``, in a
    folder in the course SCAPE layout with the template at ``template`` (``bench.correspondence.scape_layout``),
    read as ``bench/correspondence.py`` does; the template basis (at ``settings``) made once."""
    from bench.correspondence import pair_truth, read_template
    from corr_core.correspondence.dense import basis
    from corr_core.geometry.mesh_io import load_mesh

    V_s, F_s, lm_ids, lm_names, sparse_names = read_template(data, template)
    S = basis.mesh_basis(V_s, F_s, k=settings["k"], n_samples=settings["n_samples"], name="template")
    for path in tests:
        name = os.path.splitext(os.path.basename(path))[0]
        V, F = load_mesh(path)
        given = pair_truth(data, name, lm_names, lm_ids, sparse_names, len(V_s), len(V))
        yield S, lm_ids, name, V, F, given["truth"], given["landmarks"], (given["sparse"][:, 0],
                                                                          given["sparse"][:, 1])


def generated_pairs(work: str, seeds: list[int], poses: int, settings: dict):
    """The same tuples for generated bodies of other people (``bench.dense_hypotheses.generated_template``, its
    basis made at ``settings``' k and samples)."""
    from bench import dense_hypotheses as dh
    from corr_core.correspondence.landmarks import read_landmarks

    dh.SETTINGS.update(k=settings["k"], n_samples=settings["n_samples"])     # what generated_template reads
    for seed in seeds:
        root, V_s, S = dh.generated_template(work, seed, poses, decimated=True, patch_geodesics=False)
        lm_ids, _ = read_landmarks(os.path.join(root, "landmark_vids.txt"), n_vertices=len(V_s))
        sparse, _ = read_landmarks(os.path.join(root, "sparse_landmark_vids.txt"), n_vertices=len(V_s))
        for name, V, F, truth in dh.generated_targets(root, True):
            yield S, lm_ids, f"seed{seed}/{name}", V, F, truth, truth[lm_ids], (sparse, truth[sparse])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="10-11")
    ap.add_argument("--poses", type=int, default=4)
    ap.add_argument("--course-settings", action="store_true", help="k 100, 2,000 samples (the code's defaults)")
    ap.add_argument("--data", default=None, help="a folder in the course SCAPE layout instead of generated bodies")
    ap.add_argument("--pairs", type=int, default=None, help="with --data: only the first N test meshes")
    ap.add_argument("--steps", default="2,3,4,6")
    ap.add_argument("--modes", default="sparse,auto")
    ap.add_argument("--n-patches", type=int, default=None,
                    help="refine_extrinsic's patches (default: the settings', 150 at k 60, 300 at k 100)")
    ap.add_argument("--work", default=None, help="folder for the generated data (default: a temporary one)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--compare", nargs=2, default=None, metavar=("BASE", "OTHER"),
                    help="print two --json results side by side (no run)")
    args = ap.parse_args(argv)
    if args.compare:
        return compare(*args.compare)

    import tempfile

    from bench.correspondence import scape_layout
    from bench.dense_hypotheses import SETTINGS, seed_range
    from corr_core.correspondence.dense import basis, measures
    from corr_core.correspondence.dense.transfer import transfer_landmarks
    from corr_core.geometry.geodesic import GeodesicSolver

    try:
        steps = [int(s) for s in args.steps.split(",")]
    except ValueError:
        ap.error(f"--steps: comma-separated integers, got {args.steps!r}")
    modes = args.modes.split(",")
    if min(steps) < 1:
        ap.error(f"--steps: every step must be >= 1, got {args.steps}")
    if set(modes) - {"sparse", "auto"}:
        ap.error(f"--modes: sparse and/or auto, got {args.modes}")
    if args.n_patches is not None and args.n_patches < 1:
        ap.error(f"--n-patches must be >= 1, got {args.n_patches}")
    found = scape_layout(args.data, args.pairs) if args.data else None
    if args.data and found is None:
        return 2
    settings = dict(CODE_SETTINGS if args.data or args.course_settings else SETTINGS)
    if args.n_patches is not None:
        settings["n_patches"] = args.n_patches
    if args.data:
        targets = scape_targets(args.data, *found, settings)
    else:
        work = args.work or tempfile.mkdtemp(prefix="zoomout_steps_")
        targets = generated_pairs(work, seed_range(args.seeds), args.poses, settings)
    rows = []
    for S, lm_ids, name, V, F, truth, landmarks, sparse in targets:
        S.sample_distances(settings["n_patches"])           # the patches' geodesics: once per template basis
        T = basis.mesh_basis(V, F, k=settings["k"], n_samples=settings["n_samples"], name=name)
        solver = GeodesicSolver(V, F)
        evaluated = S.vids[S.samples[:settings["eval_vertices"]]]
        for mode in modes:
            for step in steps:
                t0 = time.process_time()
                vertex_map = map_with_step(S, T, mode, step, settings, sparse)
                seconds = time.process_time() - t0
                errors = measures.dense_errors(V, F, {"m": vertex_map}, truth, vertices=evaluated, solver=solver)["m"]
                _, nearest = measures.landmark_errors(V, F, transfer_landmarks(vertex_map, lm_ids), landmarks,
                                                      solver=solver)
                row = {"target": name, "mode": mode, "step": step, "mean_error": float(errors.mean()),
                       "flipped": measures.landmark_accuracy(nearest) < 0.5, "seconds": seconds}
                rows.append(row)
                print(f"{name:16s} {mode:6s} step {step:2d}  {row['mean_error']:.5f}{' F' if row['flipped'] else ''}"
                      f"  {seconds:.2f}s", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"settings": settings, "data": args.data or f"bodies seeds {args.seeds}", "rows": rows}, f,
                      indent=1)
    print_summary(rows, modes, steps)
    return 0


def print_summary(rows: list[dict], modes: list[str], steps: list[int]) -> None:
    """Per mode and step: mean / median error, lower / higher than the first step, flips, CPU seconds."""
    print(f"\n{'mode':6s} {'step':>4s} {'mean':>8s} {'median':>8s} {'lower/higher':>13s} {'flips':>5s} {'CPU s':>6s}")
    for mode in modes:
        ref = {r["target"]: r["mean_error"] for r in rows if r["mode"] == mode and r["step"] == steps[0]}
        for step in steps:
            sel = [r for r in rows if r["mode"] == mode and r["step"] == step]
            err = np.array([r["mean_error"] for r in sel])
            lower = sum(r["mean_error"] < ref[r["target"]] for r in sel)
            higher = sum(r["mean_error"] > ref[r["target"]] for r in sel)
            print(f"{mode:6s} {step:4d} {err.mean():8.5f} {np.median(err):8.5f} {f'{lower} / {higher}':>13s} "
                  f"{sum(r['flipped'] for r in sel):5d} {np.mean([r['seconds'] for r in sel]):6.2f}")
    print(f"({len({r['target'] for r in rows})} targets; lower / higher: than at step {steps[0]})")


def compare_rows(base: list[dict], other: list[dict]) -> dict:
    """Two runs' rows (``--json``'s "rows", one step each) on the targets both have, per mode: {mode: {"targets",
    "base_mean", "base_median", "other_mean", "other_median", "lower", "higher" (targets where other's error is
    lower / higher), "largest_rise", "base_flips", "other_flips", "base_seconds", "other_seconds",
    "cpu_ratio" (other / base)}}. Raises ValueError when a run holds several steps of a mode or no target is
    shared."""
    def by_mode(rows: list[dict]) -> dict:
        out: dict = {}
        for r in rows:
            if r["target"] in out.setdefault(r["mode"], {}):
                raise ValueError(f"{r['target']} {r['mode']}: several rows (several steps?); compare one step")
            out[r["mode"]][r["target"]] = r
        return out

    a, b = by_mode(base), by_mode(other)
    result = {}
    for mode in (m for m in a if m in b):
        targets = [t for t in a[mode] if t in b[mode]]
        if not targets:
            continue
        ea = np.array([a[mode][t]["mean_error"] for t in targets])
        eb = np.array([b[mode][t]["mean_error"] for t in targets])
        sa = float(np.mean([a[mode][t]["seconds"] for t in targets]))
        sb = float(np.mean([b[mode][t]["seconds"] for t in targets]))
        result[mode] = {"targets": len(targets), "base_mean": float(ea.mean()), "base_median": float(np.median(ea)),
                        "other_mean": float(eb.mean()), "other_median": float(np.median(eb)),
                        "lower": int(np.sum(eb < ea)), "higher": int(np.sum(eb > ea)),
                        "largest_rise": float(np.max(eb - ea)),
                        "base_flips": sum(bool(a[mode][t]["flipped"]) for t in targets),
                        "other_flips": sum(bool(b[mode][t]["flipped"]) for t in targets),
                        "base_seconds": sa, "other_seconds": sb, "cpu_ratio": sb / sa if sa > 0 else float("nan")}
    if not result:
        raise ValueError("the two runs share no target of a mode")
    return result


def compare(base_path: str, other_path: str) -> int:
    """Print ``compare_rows`` of two ``--json`` files; 2 with a message for an unreadable or unmatched file."""
    runs = []
    for path in (base_path, other_path):
        try:
            with open(path) as f:
                runs.append(json.load(f))
            runs[-1]["rows"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            print(f"{path}: not a --json result of this script ({type(exc).__name__}: {exc})", file=sys.stderr)
            return 2
    try:
        table = compare_rows(runs[0]["rows"], runs[1]["rows"])
    except ValueError as exc:
        print(f"{base_path}, {other_path}: {exc}", file=sys.stderr)
        return 2
    for path, run in zip((base_path, other_path), runs):
        print(f"{path}: {run.get('data', '?')}, settings {run.get('settings', '?')}")
    print(f"{'mode':6s} {'n':>3s} {'base mean (median)':>20s} {'other mean (median)':>20s} {'lower/higher':>13s} "
          f"{'largest rise':>12s} {'flips':>7s} {'CPU s':>12s} {'ratio':>6s}")
    for mode, r in table.items():
        lower_higher, flips = f"{r['lower']} / {r['higher']}", f"{r['base_flips']} / {r['other_flips']}"
        print(f"{mode:6s} {r['targets']:3d} {r['base_mean']:11.5f} ({r['base_median']:.5f}) "
              f"{r['other_mean']:11.5f} ({r['other_median']:.5f}) {lower_higher:>13s} {r['largest_rise']:12.5f} "
              f"{flips:>7s} {r['base_seconds']:5.2f} / {r['other_seconds']:4.2f} {r['cpu_ratio']:6.3f}")
    print("(lower / higher: targets where OTHER's error is; flips and CPU s: BASE / OTHER; ratio: OTHER / BASE)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
