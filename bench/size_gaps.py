"""How far each mesh's size is from its template's, once the units agree: per data folder (SCAPE layout:
meshes/template/*.obj and meshes/test/*.obj), the range of log2(sqrt(template area / mesh area)) minus its
nearest integer (``basis.size_exponent_gap``), as a length ratio, and how many meshes fall outside
``basis.SIZE_DEAD_ZONE`` (those the dense map scales to the template's area; the others it leaves as they are).

Run:  python bench/size_gaps.py FOLDER [FOLDER ...]
      e.g. ../shared/data/hw3/scape /tmp/scape_remeshed cache/generated/<hash> (the default pipeline's humans)
"""
from __future__ import annotations

import argparse
import glob
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folders", nargs="+", help="folders in the SCAPE layout")
    args = ap.parse_args(argv)

    from corr_core.correspondence.dense.basis import SIZE_DEAD_ZONE
    from corr_core.geometry.mesh_io import load_mesh
    from corr_core.geometry.primitives import face_areas

    print(f"dead zone: length ratio within {2 ** SIZE_DEAD_ZONE:.4f}")
    for folder in args.folders:
        templates = sorted(glob.glob(os.path.join(folder, "meshes", "template", "*.obj")))
        tests = sorted(glob.glob(os.path.join(folder, "meshes", "test", "*.obj")))
        if not templates or not tests:
            print(f"{folder}: no meshes/template/*.obj or meshes/test/*.obj", file=sys.stderr)
            return 2
        area = {path: float(face_areas(*load_mesh(path)).sum()) for path in templates[:1] + tests}
        e = np.array([0.5 * np.log2(area[templates[0]] / area[p]) for p in tests])
        gap = e - np.round(e)
        print(f"{folder}: {len(tests)} meshes against {os.path.basename(templates[0])}: length ratio "
              f"{2 ** gap.min():.4f} to {2 ** gap.max():.4f}, {int(np.sum(np.abs(gap) > SIZE_DEAD_ZONE))} outside "
              "the dead zone")
    return 0


if __name__ == "__main__":
    sys.exit(main())
