"""How far the evaluation's heat-method geodesics are from exact ones, at the distances dense-map errors have.

For the first ``--poses`` course SCAPE test poses: the ``dense_sparse`` map (``dense_map`` with the 5 sparse
landmarks on both meshes, defaults), then at ``--points`` farthest-point template vertices the error distance
from the mapped target vertex to the true one twice: heat method (``corr_core.geometry.geodesic``, what every
reported error uses) and exact polyhedral geodesics (libigl ``exact_geodesic``, MMP; pip ``libigl``, in the
``bench`` extra). Prints the mean error / sqrt(area) both ways and their ratio, per pose and overall.

Run:  python bench/geodesic_check.py [--poses N] [--points P]
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


def exact_distance(V: np.ndarray, F: np.ndarray, source: int, target: int) -> float:
    """Exact geodesic distance between two vertices of (V (n,3), F (m,3)) (libigl, MMP), length units of V."""
    import igl

    d = igl.exact_geodesic(V, F, np.array([source], dtype=np.int64), np.array([], dtype=np.int64),
                           np.array([target], dtype=np.int64), np.array([], dtype=np.int64))
    return float(np.ravel(d)[0])


def main(argv=None) -> dict:
    from corr_core.correspondence.dense import dense_map, mesh_basis
    from corr_core.correspondence.landmarks import read_landmarks
    from corr_core.geometry.geodesic import GeodesicSolver
    from corr_core.geometry.mesh_io import load_mesh
    from corr_core.geometry.primitives import surface_area
    from corr_core.geometry.sampling import farthest_point_samples

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=DEFAULT_DATA, help="SCAPE folder (meshes/template, meshes/test, "
                                                         "sparse_landmark_vids.txt)")
    ap.add_argument("--poses", type=int, default=3, help="first N test poses")
    ap.add_argument("--points", type=int, default=100, help="farthest-point template vertices per pose")
    args = ap.parse_args(argv)
    try:
        import igl  # noqa: F401
    except ImportError:
        sys.exit("geodesic_check: needs libigl (pip install -e \".[bench]\")")
    template = os.path.join(args.data, "meshes", "template", "mesh000.obj")
    poses = sorted(glob.glob(os.path.join(args.data, "meshes", "test", "*.obj")))[:args.poses]
    if not os.path.isfile(template) or not poses:
        sys.exit(f"geodesic_check: no SCAPE meshes under {args.data}")
    V, F = load_mesh(template)
    sparse, _ = read_landmarks(os.path.join(args.data, "sparse_landmark_vids.txt"), n_vertices=len(V))
    S = mesh_basis(V, F, k=100, name="template")
    points = farthest_point_samples(V, args.points)
    heat_all, exact_all = [], []
    for path in poses:
        Vt, Ft = load_mesh(path)
        Vt, Ft = np.ascontiguousarray(Vt, dtype=np.float64), np.ascontiguousarray(Ft, dtype=np.int64)
        p2p = dense_map(V, F, Vt, Ft, sparse, sparse, basis_template=S)
        solver, scale = GeodesicSolver(Vt, Ft), np.sqrt(surface_area(Vt, Ft))
        heat = np.array([0.0 if p2p[i] == i else solver.distance(int(i))[p2p[i]] for i in points]) / scale
        exact = np.array([0.0 if p2p[i] == i else exact_distance(Vt, Ft, int(i), int(p2p[i])) for i in points]) / scale
        heat_all.append(heat)
        exact_all.append(exact)
        print(f"{os.path.basename(path):12s} heat {heat.mean():.5f}  exact {exact.mean():.5f}  "
              f"ratio of means {heat.mean() / exact.mean():.3f}", flush=True)
    heat, exact = np.concatenate(heat_all), np.concatenate(exact_all)
    moved = exact > 0
    print(f"{'all':12s} heat {heat.mean():.5f}  exact {exact.mean():.5f}  ratio of means "
          f"{heat.mean() / exact.mean():.3f}  median ratio per point {np.median(heat[moved] / exact[moved]):.3f}")
    return {"heat": float(heat.mean()), "exact": float(exact.mean())}


if __name__ == "__main__":
    main()
