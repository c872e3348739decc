"""The dense map's tuned constants, one at a time, on generated bodies (never the course poses): the chirality
weight of the probes' point features (``init.CHIRALITY_WEIGHT``), the ARAP stiffness (``refine_deform``), the
number of patches, their size and the ICP iterations per round (``refine_extrinsic``'s ``n_patches``,
``patch_size``, ``icp_iterations``).

Per seed, ``write_humanoid_dataset(n_poses, seed, vary_bodies=True)`` (each pose another person) with a decimated,
vertex-shuffled copy of pose 1 (other connectivity); the truth (vertex i <-> i, or the generator's ground truth for
the copy) is used only to score. For every target the automatic map is made as the pipeline makes it
(``init.automatic_hypotheses``: as many hypotheses as ``hypotheses_to_refine`` decides, each upsampled and refined
with "extrinsic+spectral+deform", the least distorted kept as ``refine.refine_best`` does), once with every
constant at its default and once per other value of one constant, the others at their defaults. Printed per
target and setting: mean geodesic error / sqrt(area) of the kept map at 500 template samples, and "F" when it is
flipped (landmark accuracy < 0.5). The summary, per setting: mean and median error, the mean over the targets
where neither this setting's nor the default's kept map is flipped (and the default's there), targets lower /
higher than at the default, flipped kept maps; for the chirality weight also the hypotheses refined, the
targets where none of them was right, and the map made from the sparse landmarks (dense_sparse's
``map_from_points``, the weight's other use) refined likewise: its mean error, targets lower than at the
default, flips; and CPU seconds per target of what the setting reruns (stiffness: the deform step; patches: the
whole refinement; chirality: the automatic initialisation and the refinement).
Settings as ``bench/dense_hypotheses.py`` (k 60, 1000 samples, 150 patches: the bodies and default pipelines';
the code default 300 goes with 2000 samples, pipelines/scape.yaml, the same fraction of the samples).

Run:  python bench/dense_constants.py [--seeds 10-13] [--poses 4] [--chirality 0,0.15,0.5]
          [--stiffness 0.015,0.02,0.04,0.05,0.08] [--n-patches 75,100,300] [--patch-size 32,96,128,192]
          [--icp-iterations 2,3,4] [--json OUT]
      (an empty list skips that constant; an existing --json file is resumed: settings already in it are not run
      again, and the summary covers all of them)
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

DEFAULTS = {"chirality": 0.3, "stiffness": 0.03, "n_patches": SETTINGS["n_patches"], "patch_size": 64,
            "icp_iterations": 6}
BEFORE_DEFORM = "extrinsic+spectral"


def check_defaults() -> None:
    """The defaults above are the code's (the sweep's reference must be what the pipelines run)."""
    import inspect

    from corr_core.correspondence.dense import init, refine
    from corr_core.correspondence.dense.deform import refine_deform

    code = {"chirality": init.CHIRALITY_WEIGHT,
            "stiffness": inspect.signature(refine_deform).parameters["stiffness"].default,
            "patch_size": inspect.signature(refine.refine_extrinsic).parameters["patch_size"].default,
            "icp_iterations": inspect.signature(refine.refine_extrinsic).parameters["icp_iterations"].default}
    wrong = {k: (v, DEFAULTS[k]) for k, v in code.items() if v != DEFAULTS[k]}
    if wrong:
        raise SystemExit(f"bench/dense_constants.py: DEFAULTS differ from the code's (code, bench): {wrong}")


class Target:
    """One target's maps, made lazily and shared between the settings (the default's hypotheses and their maps
    before the deform step serve every stiffness)."""

    def __init__(self, S, T, V_t, F_t, truth, landmarks, sparse):
        from corr_core.geometry.geodesic import GeodesicSolver

        self.S, self.T, self.V_t, self.F_t, self.truth, self.landmarks = S, T, V_t, F_t, truth, landmarks
        self.sparse = sparse
        self.solver = GeodesicSolver(V_t, F_t)
        self.vertices = S.vids[S.samples[:SETTINGS["eval_vertices"]]]
        self._starts: dict[float, tuple] = {}
        self._before_deform = None

    def starts(self, chirality: float) -> tuple[list, float]:
        """(upsampled hypothesis maps, CPU s) of ``automatic_hypotheses`` at this chirality weight."""
        from corr_core.correspondence.dense import init, upsample_spectral

        if chirality not in self._starts:
            t0 = time.process_time()
            hyps = init.automatic_hypotheses(self.S, self.T, k_init=SETTINGS["k_init"], k_end=SETTINGS["k"],
                                             chirality_weight=chirality)
            maps = [upsample_spectral(self.S, self.T, C, p2p) for C, p2p in hyps]
            self._starts[chirality] = (maps, time.process_time() - t0)
        return self._starts[chirality]

    def before_deform(self) -> tuple[list, float]:
        """(default hypotheses refined by "extrinsic+spectral", CPU s)."""
        from corr_core.correspondence.dense import refine

        if self._before_deform is None:
            maps, _ = self.starts(DEFAULTS["chirality"])
            t0 = time.process_time()
            out = [refine.refine_map(self.S, self.T, m, BEFORE_DEFORM, {"extrinsic": extrinsic_options()})
                   for m in maps]
            self._before_deform = (out, time.process_time() - t0)
        return self._before_deform

    def from_points(self, chirality: float) -> dict:
        """The map from the sparse landmarks (``map_from_points``, as dense_sparse makes it, its point features at
        this chirality weight), refined with the defaults: {"sparse_error", "sparse_flipped"}."""
        from corr_core.correspondence.dense import init, refine, upsample_spectral

        ps, pt = self.S.to_local(self.sparse), self.T.to_local(self.truth[self.sparse])
        features = (init.point_features(self.S, ps, chirality_weight=chirality),
                    init.point_features(self.T, pt, chirality_weight=chirality))
        C, p2p = init.map_from_points(self.S, self.T, self.sparse, self.truth[self.sparse],
                                      k_init=SETTINGS["k_init"], k_end=SETTINGS["k"], features=features)
        refined = refine.refine_map(self.S, self.T, upsample_spectral(self.S, self.T, C, p2p), refine.DEFAULT_REFINE,
                                    {"extrinsic": extrinsic_options()})
        row = self.score([refined])
        return {"sparse_error": row["mean_error"], "sparse_flipped": row["flipped"]}

    def score(self, refined: list) -> dict:
        """The kept map (least ``map_distortion``, ties to the better ranked) of refined hypotheses, scored."""
        from corr_core.correspondence.dense import measures, refine
        from corr_core.correspondence.dense.basis import map_to_original
        from corr_core.correspondence.dense.transfer import transfer_landmarks

        def accuracy(vertex_map):
            _, nearest = measures.landmark_errors(self.V_t, self.F_t, transfer_landmarks(vertex_map, self.landmarks),
                                                  self.truth[self.landmarks], solver=self.solver)
            return measures.landmark_accuracy(nearest)

        vertex_maps = [map_to_original(self.S, self.T, p2p) for p2p in refined]
        kept = int(np.argmin([refine.map_distortion(self.S, self.T, p2p) for p2p in refined]))
        error = measures.dense_errors(self.V_t, self.F_t, {"m": vertex_maps[kept]}, self.truth,
                                      vertices=self.vertices, solver=self.solver)["m"]
        right = [accuracy(vm) >= 0.5 for vm in vertex_maps]
        return {"mean_error": float(error.mean()), "flipped": not right[kept], "refined": len(refined),
                "kept": kept, "any_right": any(right)}


def extrinsic_options(**changed) -> dict:
    return {"n_patches": DEFAULTS["n_patches"], "patch_size": DEFAULTS["patch_size"],
            "icp_iterations": DEFAULTS["icp_iterations"], **changed}


def run_setting(t: Target, name: str, value: float) -> dict:
    """Score of one setting (``name`` = ``value``, the other constants at their defaults) and its CPU s."""
    from corr_core.correspondence.dense import refine
    from corr_core.correspondence.dense.deform import refine_deform

    if name == "stiffness" or (name, value) == ("default", 0):
        st = DEFAULTS["stiffness"] if name == "default" else value
        maps, t_before = t.before_deform()
        t0 = time.process_time()
        refined = [refine_deform(t.S, t.T, m, stiffness=st) for m in maps]
        t_deform = time.process_time() - t0
        if name == "default":                    # every group's seconds are counted from this run
            t_init = t.starts(DEFAULTS["chirality"])[1]
            seconds = {"stiffness": t_deform, "patches": t_before + t_deform,
                       "chirality": t_init + t_before + t_deform}
            return {**t.score(refined), **t.from_points(DEFAULTS["chirality"]), "seconds": seconds}
        return {**t.score(refined), "seconds": t_deform}
    maps, t_init = t.starts(value if name == "chirality" else DEFAULTS["chirality"])
    options = {"extrinsic": extrinsic_options(**({name: int(value)} if name != "chirality" else {})),
               "deform": {"stiffness": DEFAULTS["stiffness"]}}
    t0 = time.process_time()
    refined = [refine.refine_map(t.S, t.T, m, refine.DEFAULT_REFINE, options) for m in maps]
    seconds = time.process_time() - t0 + (t_init if name == "chirality" else 0.0)
    sparse = t.from_points(value) if name == "chirality" else {}
    return {**t.score(refined), **sparse, "seconds": seconds}


GROUPS = (("chirality", "chirality"), ("stiffness", "stiffness"), ("n_patches", "patches"),
          ("patch_size", "patches"), ("icp_iterations", "patches"))


def setting_key(name: str, value: float) -> str:
    return f"{name}={value:g}"


def default_as(row: dict, group: str) -> dict:
    """The default run's row as one setting of ``group`` (its seconds: what that group reruns)."""
    return {**row, "seconds": row["seconds"][group]}


def summary(results: list[dict], grid: dict) -> None:
    print(f"\n{len(results)} targets; per setting: mean error of the kept map (median; mean over the targets right at "
          "this setting and at the default, vs the default's), targets lower / higher than at the default, flipped "
          "kept maps, CPU s per target of what the setting reruns")
    for name, group in GROUPS:
        if not grid[name]:
            continue
        print(f"{name} (default {DEFAULTS[name]:g}):")
        for value in sorted(set(grid[name]) | {DEFAULTS[name]}):
            key = setting_key(name, value)
            rows = [(default_as(r["settings"]["default"], group) if value == DEFAULTS[name] else r["settings"][key],
                     r["settings"]["default"]) for r in results if key in r["settings"] or value == DEFAULTS[name]]
            if len(rows) < len(results):
                print(f"  {value:>6g}: run on {len(rows)} of {len(results)} targets only")
                continue
            errs = np.array([row["mean_error"] for row, _ in rows])
            base = np.array([d["mean_error"] for _, d in rows])
            extra = ""
            if name == "chirality":
                extra = (f"; hypotheses refined {np.mean([row['refined'] for row, _ in rows]):.2f} per target, "
                         f"none of them right on {sum(not row['any_right'] for row, _ in rows)}; from the sparse "
                         f"points {np.mean([row['sparse_error'] for row, _ in rows]):.5f}, lower on "
                         f"{sum(row['sparse_error'] < d['sparse_error'] for row, d in rows)}, flipped "
                         f"{sum(row['sparse_flipped'] for row, _ in rows)}")
            mark = "  (default)" if value == DEFAULTS[name] else ""
            both = np.array([not row["flipped"] and not d["flipped"] for row, d in rows])
            print(f"  {value:>6g}: {errs.mean():.5f} (median {np.median(errs):.5f}; on the {int(both.sum())} right at "
                  f"both {errs[both].mean():.5f} vs {base[both].mean():.5f})  lower on {int(np.sum(errs < base))}, "
                  f"higher on {int(np.sum(errs > base))} of {len(rows)}; flipped "
                  f"{sum(row['flipped'] for row, _ in rows)}{extra}; "
                  f"{np.mean([row['seconds'] for row, _ in rows]):.1f} s{mark}")


def floats(text: str) -> list[float]:
    return [float(x) for x in text.split(",") if x.strip()]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="10-13")
    ap.add_argument("--poses", type=int, default=4)
    ap.add_argument("--chirality", default="0,0.15,0.5", help="values besides the default (always run)")
    ap.add_argument("--stiffness", default="0.015,0.02,0.04,0.05,0.08")
    ap.add_argument("--n-patches", default="75,100,300")
    ap.add_argument("--patch-size", default="32,96,128,192")
    ap.add_argument("--icp-iterations", default="", help="e.g. 2,3,4 (default: none besides the code's 6)")
    ap.add_argument("--work", default=None, help="folder for the generated data (default: a temporary one)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    check_defaults()
    grid = {"chirality": floats(args.chirality), "stiffness": floats(args.stiffness),
            "n_patches": floats(args.n_patches), "patch_size": floats(args.patch_size),
            "icp_iterations": floats(args.icp_iterations)}
    wanted = [("default", 0)] + [(name, v) for name, _ in GROUPS for v in grid[name] if v != DEFAULTS[name]]

    from corr_core.correspondence.dense import basis
    from corr_core.correspondence.landmarks import read_landmarks

    work = args.work or tempfile.mkdtemp(prefix="dense_constants_")
    results = resumed_results(args.json, seed_range(args.seeds))   # resume: settings already in the file are kept
    by_target = {(r["seed"], r["mesh"]): r for r in results}
    for seed in seed_range(args.seeds):
        root, V_s, S = generated_template(work, seed, args.poses)
        landmarks, _ = read_landmarks(os.path.join(root, "landmark_vids.txt"), n_vertices=len(V_s))
        sparse, _ = read_landmarks(os.path.join(root, "sparse_landmark_vids.txt"), n_vertices=len(V_s))
        for name, V_t, F_t, truth in generated_targets(root, True):
            record = by_target.get((seed, name))
            todo = [(n, v) for n, v in wanted if record is None or
                    ("default" if n == "default" else setting_key(n, v)) not in record["settings"]]
            if not todo:
                continue
            if record is None:
                record = {"seed": seed, "mesh": name, "n_vertices": len(V_t), "settings": {}}
                results.append(record)
                by_target[(seed, name)] = record
            T = basis.mesh_basis(V_t, F_t, k=SETTINGS["k"], n_samples=SETTINGS["n_samples"])
            target = Target(S, T, V_t, F_t, truth, landmarks, sparse)
            for n, v in todo:
                record["settings"]["default" if n == "default" else setting_key(n, v)] = run_setting(target, n, v)
                if args.json:
                    with open(args.json, "w") as fh:
                        json.dump(results, fh, indent=1)
            print(f"seed {seed} {name} ({len(V_t)} v): " + "  ".join(
                f"{k} {r['mean_error']:.4f}{' F' if r['flipped'] else ''}" for k, r in record["settings"].items()),
                flush=True)
    results = [by_target[k] for k in sorted(by_target)]
    summary(results, grid)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
