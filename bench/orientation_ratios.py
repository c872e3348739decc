"""Which way do the faces of a set of meshes point? Per mesh glob: the smallest and largest signed volume ratio
(``repair.signed_volume_ratio``: near +1 outward, -1 inward, near 0 flat) of the meshes, and, for the first mesh,
the ratio of each half cut off by a plane through its vertex median along x and along z (open pieces). It chose
``repair.OUTWARD_MARGIN`` (a surface is turned outward below -0.2): every outward mesh and half lies far above it.

Run:  python bench/orientation_ratios.py [GLOB ...]
      (default: the course SCAPE poses, /tmp/scape_remeshed from bench/remesh_scape.py, and the meshes generated
      by the pipelines in cache/generated)
"""
from __future__ import annotations

import glob
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_GLOBS = [os.path.join(ROOT, "..", "shared", "data", "hw3", "scape", "meshes", "*", "*.obj"),
                 "/tmp/scape_remeshed/meshes/*/*.obj", os.path.join(ROOT, "cache", "generated", "*", "meshes", "*",
                                                                    "*.obj")]


def main(argv=None) -> int:
    from corr_core.geometry.mesh_io import load_mesh
    from corr_core.geometry.repair import signed_volume_ratio

    for pattern in (argv if argv else DEFAULT_GLOBS):
        paths = sorted(glob.glob(pattern))
        if not paths:
            print(f"{pattern}: no mesh")
            continue
        ratios = [signed_volume_ratio(*load_mesh(p)) for p in paths]
        V, F = load_mesh(paths[0])
        centres = V[F].mean(axis=1)
        halves = [signed_volume_ratio(V, F[centres[:, axis] > np.median(V[:, axis])]) for axis in (0, 2)]
        print(f"{pattern}: {len(paths)} meshes, ratio {min(ratios):.3f} to {max(ratios):.3f}; halves of "
              f"{os.path.basename(paths[0])} (x, z) {halves[0]:.3f}, {halves[1]:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
