"""Möbius voting's three numbers (K, power, K_scale) swept on generated humanoids (never the course poses).

Per seed, ``write_humanoid_dataset(n_poses, seed)`` (the generator of pipeline.yaml's humans: the same body in
random poses, vertex i <-> i; ``--other-bodies``: every pose another person too); every mesh is loaded, repaired
and flattened as the pipeline's ``corr.mesh`` / ``corr.flatten`` do it on such data (300 farthest-point samples:
the generator writes no ``uniform_sample_vids.txt``), and every test mesh is matched to the template by
``matchers.match_mobius`` (what the ``corr.match_mobius`` stage calls; metric "surface") with each value of
``--K``, ``--power`` and ``--K-scale``, one number varied at a time, the other two at the grid's centre (K 0.5,
power 4, K_scale 0.3: the setting before this sweep re-fitted K_scale).
Printed per target: the sparse accuracy per setting; the summary, per setting: accuracy on the sparse landmarks
(their triplets vote) and on all landmarks (extended by the consensus maps), over every target, and the mean
geodesic error / sqrt(area) of the dense map from the best map at 200 template vertices; (pipelines) marks the
setting every pipeline uses (K 0.5, power 4, K_scale 0.7: the ``corr.match_mobius`` defaults).

Run:  python bench/mobius_sweep.py [--seeds 10-12] [--poses 6] [--K 0.3,0.5,0.8] [--power 2,4,8]
          [--K-scale 0.2,0.3,0.5,0.7,1.0] [--other-bodies] [--json OUT]
      (an existing --json file is resumed: settings already in it are not run again)
"""
from __future__ import annotations

import argparse
import glob
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

from bench.dense_hypotheses import resumed_results, seed_range  # noqa: E402

DEFAULT = (0.5, 4.0, 0.3)          # K, power, K_scale: the grid's centre (the stage's setting before the re-fit)
PIPELINES = (0.5, 4.0, 0.7)        # the corr.match_mobius defaults, which every pipeline uses


def prepared_mesh(path: str, landmark_ids: np.ndarray) -> tuple[dict, dict]:
    """({"V", "F", "area"}, ``flattening_features``) of one mesh, as ``corr.mesh`` and ``corr.flatten`` make them."""
    from corr_core.correspondence import mesh_features
    from corr_core.geometry.mesh_io import load_mesh
    from corr_core.geometry.primitives import surface_area
    from corr_core.geometry.repair import repair_mesh

    V, F = load_mesh(path)
    F, _ = repair_mesh(V, F, os.path.basename(path), keep_largest_component=True)
    F = F.astype(np.int64)
    return {"V": V, "F": F, "area": surface_area(V, F)}, mesh_features.flattening_features(V, F, landmark_ids)


def floats(text: str) -> list[float]:
    return [float(x) for x in text.split(",") if x.strip()]


def setting_key(K: float, power: float, K_scale: float) -> str:
    return f"K={K:g} power={power:g} K_scale={K_scale:g}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="10-12")
    ap.add_argument("--poses", type=int, default=6)
    ap.add_argument("--K", default="0.3,0.5,0.8")
    ap.add_argument("--power", default="2,4,8")
    ap.add_argument("--K-scale", default="0.2,0.3,0.5,0.7,1.0")
    ap.add_argument("--other-bodies", action="store_true", help="every pose another person (pipelines/bodies.yaml)")
    ap.add_argument("--work", default=None, help="folder for the generated data (default: a temporary one)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    grid = sorted({DEFAULT} | {(K, DEFAULT[1], DEFAULT[2]) for K in floats(args.K)}
                  | {(DEFAULT[0], p, DEFAULT[2]) for p in floats(args.power)}
                  | {(DEFAULT[0], DEFAULT[1], s) for s in floats(args.K_scale)},
                  key=lambda g: (g[0] != DEFAULT[0], g[1] != DEFAULT[1], g))

    from corr_core.correspondence import matchers
    from corr_core.correspondence.landmarks import read_landmarks, subset_positions
    from corr_core.generate.humanoid import write_humanoid_dataset

    work = args.work or tempfile.mkdtemp(prefix="mobius_sweep_")
    results = resumed_results(args.json, seed_range(args.seeds))   # resume: settings already in the file are kept
    by_target = {(r["seed"], r["mesh"]): r for r in results}
    for seed in seed_range(args.seeds):
        root = os.path.join(work, f"{'bodies' if args.other_bodies else 'same'}_seed{seed}")
        if not os.path.isdir(root):
            write_humanoid_dataset(root, n_poses=args.poses, seed=seed, vary_bodies=args.other_bodies)
        ids, _ = read_landmarks(os.path.join(root, "landmark_vids.txt"))
        sparse = subset_positions(ids, read_landmarks(os.path.join(root, "sparse_landmark_vids.txt"))[0])
        template = None
        for path in sorted(glob.glob(os.path.join(root, "meshes", "test", "*.obj"))):
            name = os.path.splitext(os.path.basename(path))[0]
            record = by_target.setdefault((seed, name), {"seed": seed, "mesh": name, "settings": {}})
            todo = [g for g in grid if setting_key(*g) not in record["settings"]]
            if not todo:
                continue
            if record not in results:
                results.append(record)
            template = template or prepared_mesh(os.path.join(root, "meshes", "template", "mesh000.obj"), ids)
            mesh, flat = prepared_mesh(path, ids)
            for K, power, K_scale in todo:
                t0 = time.process_time()
                out = matchers.match_mobius(template[1], flat, template[0], mesh, sparse, K=K, power=power,
                                            K_scale=K_scale)
                record["settings"][setting_key(K, power, K_scale)] = {
                    "sparse": float(np.mean(np.asarray(out["sparse"]) == np.arange(len(sparse)))),
                    "all": float(np.mean(np.asarray(out["all"]) == np.arange(len(ids)))),
                    "dense_error": float(np.mean(out["dense_errors"])), "seconds": time.process_time() - t0}
            if args.json:
                with open(args.json, "w") as fh:
                    json.dump(results, fh, indent=1)
            print(f"seed {seed} {name}: sparse accuracy " + "  ".join(
                f"{k.replace(' ', ',')} {r['sparse']:.2f}" for k, r in record["settings"].items()), flush=True)
    results = [by_target[k] for k in sorted(by_target)]
    print(f"\n{len(results)} targets ({'other bodies' if args.other_bodies else 'same body'}, seeds {args.seeds}, "
          f"{len(sparse)} sparse of {len(ids)} landmarks); per setting: accuracy on the sparse and on all "
          "landmarks, mean dense-map error, CPU s per target")
    for g in grid:
        key = setting_key(*g)
        rows = [r["settings"][key] for r in results if key in r["settings"]]
        mark = "  (pipelines)" if g == PIPELINES else "  (grid centre)" if g == DEFAULT else ""
        print(f"  {key:<28}: sparse {np.mean([r['sparse'] for r in rows]):.3f}  all "
              f"{np.mean([r['all'] for r in rows]):.3f}  dense {np.mean([r['dense_error'] for r in rows]):.4f}  "
              f"({np.mean([r['seconds'] for r in rows]):.2f} s, {len(rows)} targets){mark}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
