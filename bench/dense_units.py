"""Does the dense map depend on the target's units, size or position? One course pose mapped as it is and scaled
by each factor (and moved far from the origin): per factor, the automatic map's share of template vertices sent
to their exact vertex (the course poses share the template's triangles: vertex i <-> i is the truth), its mean
geodesic error / sqrt(area) at 500 farthest-point template vertices, and the share of vertices mapped as with
factor 1; then the same for the target as it is with every face reversed (normals pointing inward), and cut
along a seam (a front and a back piece, the seam's vertices repeated with new ids; a copy counts as its
original), and with fins (``corr_core.generate.defects``).

Run:  python bench/dense_units.py [--data ../shared/data/hw3/scape] [--pose mesh002]
          [--factors 1,1.2,1.41,0.78,2,1000,0.001,0.0254,39.37]
"""
from __future__ import annotations

import argparse
import os
import sys
import warnings

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import one_blas_thread  # noqa: E402

if __name__ == "__main__":
    one_blas_thread()

import numpy as np  # noqa: E402

DEFAULT_DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "shared", "data",
                            "hw3", "scape")
N_FINS, FIN_HEIGHT = 30, 2.0   # fins on the target in the last line, their height in mean edge lengths
OFFSET = 5000.0   # added to every coordinate of the scaled target (units of the scaled mesh)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=DEFAULT_DATA, help="course scape/ folder")
    ap.add_argument("--pose", default="mesh002")
    ap.add_argument("--factors", default="1,1.2,1.41,0.78,2,1000,0.001,0.0254,39.37")
    args = ap.parse_args(argv)

    from corr_core.correspondence.dense import dense_map, measures
    from corr_core.generate.defects import cut_along_a_seam, with_fins
    from corr_core.geometry.mesh_io import load_mesh
    from corr_core.geometry.sampling import farthest_point_samples

    Vs, Fs = load_mesh(os.path.join(args.data, "meshes", "template", "mesh000.obj"))
    Vt, Ft = load_mesh(os.path.join(args.data, "meshes", "test", f"{args.pose}.obj"))
    if not np.array_equal(Fs, Ft):
        print(f"{args.pose}: not the template's triangles; the truth vertex i <-> i does not hold", file=sys.stderr)
        return 2
    truth = np.arange(len(Vs))
    vertices = farthest_point_samples(Vs, 500, start=0)
    first = None
    print(f"template -> {args.pose} scaled by each factor (+{OFFSET} on every coordinate except at factor 1), "
          "dense_auto")
    for factor in (float(f) for f in args.factors.split(",")):
        V = Vt if factor == 1.0 else Vt * factor + OFFSET
        p2p = dense_map(Vs, Fs, V, Ft)
        err = measures.dense_errors(V, Ft, {"m": p2p}, truth, vertices=vertices)["m"].mean()
        first = p2p if first is None else first
        print(f"  factor {factor:g}: exact vertex {np.mean(p2p == truth):.3f}  mean error {err:.4f}  "
              f"same as the first factor's map {np.mean(p2p == first):.3f}", flush=True)
    inward = np.ascontiguousarray(Ft[:, ::-1])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # mesh_basis says it reverses them: the point of this line
        p2p = dense_map(Vs, Fs, Vt, inward)
    err = measures.dense_errors(Vt, inward, {"m": p2p}, truth, vertices=vertices)["m"].mean()
    print(f"  as it is, every face reversed (pointing inward): exact vertex {np.mean(p2p == truth):.3f}  "
          f"mean error {err:.4f}  same as the first factor's map {np.mean(p2p == first):.3f}", flush=True)
    centroid_z = Vt[Ft].mean(axis=1)[:, 2]
    V_cut, F_cut, shared, _ = cut_along_a_seam(Vt, Ft, centroid_z > np.median(centroid_z))   # front and back
    p2p = dense_map(Vs, Fs, V_cut, F_cut)
    on_original = np.where(p2p >= len(Vt), shared[np.clip(p2p - len(Vt), 0, len(shared) - 1)], p2p)
    err = measures.dense_errors(Vt, Ft, {"m": on_original}, truth, vertices=vertices)["m"].mean()
    print(f"  as it is, cut along a seam ({len(shared)} vertices repeated): exact vertex "
          f"{np.mean(on_original == truth):.3f}  mean error {err:.4f}  same as the first factor's map "
          f"{np.mean(on_original == first):.3f}", flush=True)
    V_fins, F_fins = with_fins(Vt, Ft, N_FINS, height=FIN_HEIGHT)
    p2p = dense_map(Vs, Fs, V_fins, F_fins)
    on_apex = p2p >= len(Vt)
    fin_base = F_fins[len(Ft):, 0]                                   # apex n + i stands on vertex fin_base[i]
    on_surface = np.where(on_apex, fin_base[np.clip(p2p - len(Vt), 0, N_FINS - 1)], p2p)
    err = measures.dense_errors(Vt, Ft, {"m": on_surface}, truth, vertices=vertices)["m"].mean()
    print(f"  as it is, with {N_FINS} fins (triangles {FIN_HEIGHT:g} edges tall standing on edges, non-manifold): "
          f"exact vertex "
          f"{np.mean(p2p == truth):.3f}  mean error {err:.4f} (an apex counted at its fin's base vertex)  "
          f"on an apex {int(on_apex.sum())}  same as the first factor's map {np.mean(p2p == first):.3f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
