"""The same poses with and without their vertex ids shuffled, through pipelines/scape.yaml.

Writes a generated humanoid dataset (``write_humanoid_dataset``: template + ``--poses`` poses, the default
pipeline's generator and mesh size) and a copy whose test meshes have their vertices in a random order (same
counts, triangles renumbered), the permutation as ``ground_truth/<mesh>.txt`` and no ``landmarks/`` folder
(the shared landmark file names the template's ids, so it does not apply). Runs scape.yaml on both with the
default pipeline's dense settings and prints, per pose and method, landmark accuracy and mean geodesic error /
sqrt(area) (``corr.dense_measures``, read with ``stages.api.result``), then why ``dense_sparse`` skipped the
shuffled poses.

Run:  python bench/shuffled_ids.py [--poses N] [--work FOLDER]
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

# the dense settings of pipeline.yaml (k 60, 1000 samples, 150 patches, 500 evaluated vertices)
SETS = ["dense_basis.k=60", "dense_basis.n_samples=1000", "dense_sparse_init.k_init=30", "dense_sparse_init.k_end=60",
        "dense_auto_init.k_init=30", "dense_auto_init.k_end=60",
        "dense_template.n_patches=150", "dense_sparse.n_patches=150", "dense_auto.n_patches=150",
        "dense_measures.n_points=500", "evaluate.frequency_figures=false"]


def shuffled_copy(src: str, dst: str, seed: int = 0) -> None:
    """``dst``: ``src`` with every test mesh's vertex ids permuted, the truth file per mesh, no landmarks/."""
    from corr_core.geometry.mesh_io import load_mesh, save_obj

    shutil.copytree(src, dst)
    shutil.rmtree(os.path.join(dst, "landmarks"), ignore_errors=True)
    os.makedirs(os.path.join(dst, "ground_truth"), exist_ok=True)
    rng = np.random.default_rng(seed)
    for name in sorted(os.listdir(os.path.join(src, "meshes", "test"))):
        V, F = load_mesh(os.path.join(src, "meshes", "test", name))
        perm = rng.permutation(len(V))               # new id of vertex j
        save_obj(os.path.join(dst, "meshes", "test", name), V[np.argsort(perm)], perm[F])
        with open(os.path.join(dst, "ground_truth", os.path.splitext(name)[0] + ".txt"), "w") as fh:
            fh.write("".join(f"{t}\n" for t in perm))


def scores(pipeline: str, root: str, cache: str, meshes: list[str]) -> dict:
    from corr_core.correspondence.dense import measures
    from stages import api

    params = dict(s.split("=", 1) for s in [f"data.root={root}", *SETS])
    out = {}
    for m in meshes:
        r = api.result(pipeline, "dense_measures", m, params=params, cache_dir=cache)
        out[m] = {k: (measures.landmark_accuracy(r["nearest"][k]), float(np.mean(r["errors"][k])))
                  for k in ("dense_sparse", "dense_auto") if k in r.get("errors", {})}
    return out


def main(argv=None) -> None:
    from corr_core.generate import write_humanoid_dataset
    from stages import api

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=3)
    ap.add_argument("--work", default="/tmp/shuffled_ids")
    args = ap.parse_args(argv)
    pipeline = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "pipelines", "scape.yaml")
    plain, shuffled, cache = (os.path.join(args.work, d) for d in ("plain", "shuffled", "cache"))
    if not os.path.isdir(plain):
        write_humanoid_dataset(plain, n_poses=args.poses, seed=0)
    if not os.path.isdir(shuffled):
        shuffled_copy(plain, shuffled)
    meshes = [f"mesh{i:03d}" for i in range(1, args.poses + 1)]
    results = {}
    for label, root in (("unshuffled", plain), ("shuffled", shuffled)):
        api.run(pipeline, [f"data.root={root}", *SETS], cache_dir=cache, output_dir=os.path.join(args.work, label),
                quiet=True, workers=2)
        results[label] = scores(pipeline, root, cache, meshes)
    print(f"{'pose':<8} {'method':<13} {'unshuffled acc / mean err':>26} {'shuffled acc / mean err':>24}")
    for m in meshes:
        for k in ("dense_sparse", "dense_auto"):
            a = results["unshuffled"][m].get(k)
            b = results["shuffled"][m].get(k)
            fmt = lambda x: f"{x[0]:.2f} / {x[1]:.5f}" if x else "skipped"  # noqa: E731
            print(f"{m:<8} {k:<13} {fmt(a):>26} {fmt(b):>24}")
    m = api.metrics(api.plan_pipeline(pipeline, [f"data.root={shuffled}", *SETS], cache_dir=cache))
    for mesh, why in m.get("dense_skipped", {}).get("dense_sparse", {}).items():
        print(f"dense_sparse skipped {mesh}: {why}")


if __name__ == "__main__":
    main()
