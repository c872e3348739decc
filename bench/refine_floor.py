"""Fixed points of the pointwise refinements near the truth, on the course SCAPE poses.

Each refinement step of ``corr_core.correspondence.dense`` starts from the *true* map (vertex i <-> vertex i) of
template mesh000 -> a test pose; the mean geodesic error / sqrt(area) it ends at (2,000 farthest-point template
vertices) is how far its own optimum sits from the truth: the floor the step can reach from a perfect start.
Uses only the two meshes (no landmark, no sample file).

Run:  python bench/refine_floor.py [--poses N]      (default: the first 5 test poses)
"""
from __future__ import annotations

import argparse
import glob
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import SCAPE as DEFAULT_DATA, one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()

import numpy as np  # noqa: E402

STEPS = ("extrinsic", "spectral", "deform")


def main(argv=None) -> dict:
    from corr_core.correspondence.dense import measures, mesh_basis, refine_map
    from corr_core.geometry.mesh_io import load_mesh
    from corr_core.geometry.sampling import farthest_point_samples

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=DEFAULT_DATA, help="SCAPE folder (meshes/template, meshes/test)")
    ap.add_argument("--poses", type=int, default=5, help="first N test poses")
    args = ap.parse_args(argv)
    template = os.path.join(args.data, "meshes", "template", "mesh000.obj")
    poses = sorted(glob.glob(os.path.join(args.data, "meshes", "test", "*.obj")))[:args.poses]
    if not os.path.isfile(template) or not poses:
        sys.exit(f"refine_floor: no SCAPE meshes under {args.data} (meshes/template/mesh000.obj, meshes/test/*.obj)")
    V, F = load_mesh(template)
    S = mesh_basis(V, F, k=100, name="template")
    vertices = farthest_point_samples(V, 2000)
    rows = {}
    for path in poses:
        Vt, Ft = load_mesh(path)
        T = mesh_basis(Vt, Ft, k=100, name=os.path.basename(path))
        truth = np.arange(len(V))
        maps = {step: refine_map(S, T, truth, step) for step in STEPS}
        errors = measures.dense_errors(Vt, Ft, maps, truth, vertices=vertices)
        rows[os.path.basename(path)] = {step: float(errors[step].mean()) for step in STEPS}
        print(f"{os.path.basename(path):12s} " + "  ".join(f"{s} {rows[os.path.basename(path)][s]:.4f}" for s in STEPS),
              flush=True)
    mean = {step: float(np.mean([r[step] for r in rows.values()])) for step in STEPS}
    print(f"{'mean':12s} " + "  ".join(f"{s} {mean[s]:.4f}" for s in STEPS))
    return mean


if __name__ == "__main__":
    main()
