"""The course SCAPE set with every mesh triangulated on its own: connectivity invariance of the dense maps.

Every mesh (the template and each pose) is decimated by itself with Open3D's quadric decimation
(``simplify_quadric_decimation``) to a vertex count drawn per mesh (``numpy.random.default_rng(seed)``, uniform
in 3,500..6,000; the triangle target is twice that), cleaned (largest connected component, no unreferenced
vertex) and its vertex ids shuffled with the same generator, so no two meshes share a triangulation or a
numbering and nothing can rely on vertex ids.

Written to ``--out`` (outside the repository; a folder that exists, is not empty and was not made by this script
is refused), in the layout the pipelines (``pipelines/scape.yaml``) and ``bench/correspondence.py`` read:
``meshes/template/mesh000.obj``, ``meshes/test/meshNNN.obj``; ``landmark_vids.txt`` and
``sparse_landmark_vids.txt`` (the template's, ``vid,Name``, 0-based); ``landmarks/<mesh>.txt`` (every mesh's
own 20 landmarks, same format); ``ground_truth/<mesh>.txt`` (per pose: the true target vertex of each template
vertex, one id a line, 0-based).

Ground truth: remeshed template vertex v -> nearest original template vertex o (Euclidean) -> vertex o of the
original pose (the course meshes share triangles: o is the same point) -> nearest remeshed pose vertex.
Landmarks: the original landmark vertex -> the nearest remeshed vertex of the same mesh. Both snaps move a
point; their distances / sqrt(remeshed area), printed per mesh (mean and max), are the floor of any error
measured on this set.

With ``--floor``: also the error of the exact map, measured as ``bench/correspondence.py`` measures (geodesic
on the pose / sqrt(area) at the same 2,000 farthest-point template vertices) against the written ground truth.
The exact map sends a remeshed template vertex to the closest point of the original template's surface (any
point of a triangle, not a vertex), that point of the original pose, and its nearest remeshed pose vertex: the
best map a method can return on these meshes; its error is what the ground truth's snap to original vertices
costs every method.

With ``--carry MAPS`` (no remeshing: the set in ``--out`` is scored): maps between the *original* meshes
(``bench/correspondence.py --save-maps MAPS`` on the course data, MAPS/<method>/<pose>.txt) carried to the
remeshed meshes (``carried_map``: the closest point of the original template, the same barycentric combination of
its corners' images, the nearest remeshed pose vertex) and scored like the exact map: what a method exactly as
accurate as on the original meshes scores on this set, the reference its own remeshed errors are compared with.

Run:  python bench/remesh_scape.py [--data SCAPE] [--out /tmp/scape_remeshed] [--seed 0] [--poses N] [--floor]
      python bench/remesh_scape.py --carry MAPS [--out /tmp/scape_remeshed] [--poses N] [--against REM.json]
          (--against: the methods' own errors on the remeshed set, bench/correspondence.py --json REM.json --data
          /tmp/scape_remeshed, or on the original meshes, against their carried errors)
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import shutil
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import ROOT, SCAPE as DEFAULT_DATA  # noqa: E402

import numpy as np  # noqa: E402

MIN_VERTICES, MAX_VERTICES = 3500, 6000
MARKER = ".made_by_remesh_scape"          # marks a folder this script created (it may then be overwritten)


def decimate(V: np.ndarray, F: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """Open3D quadric decimation of (V (n,3), F (m,3)) to 2 * n_vertices triangles, then cleaned: the largest
    connected component, no unreferenced vertex. Returns V2 (n2,3) float64, F2 (m2,3) int64, vertices in
    Open3D's order."""
    from corr_core.open3d_loader import load_open3d
    from corr_core.geometry.primitives import largest_component

    o3d = load_open3d()
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(V, np.float64)),
                                     o3d.utility.Vector3iVector(np.asarray(F, np.int32)))
    mesh = mesh.simplify_quadric_decimation(target_number_of_triangles=2 * int(n_vertices))
    V2, F2, _ = largest_component(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.triangles, np.int64))
    return np.asarray(V2, np.float64), np.asarray(F2, np.int64)


def shuffle_vertices(V: np.ndarray, F: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The same mesh with its vertex ids permuted by ``rng``: V (n,3), F (m,3) -> V' (n,3), F' (m,3)."""
    new_id = rng.permutation(len(V))                 # vertex j becomes vertex new_id[j]
    return V[np.argsort(new_id)], new_id[F]


def sqrt_area(V: np.ndarray, F: np.ndarray) -> float:
    """sqrt of the surface area of (V (n,3), F (m,3)): the scale every error is divided by."""
    from corr_core.geometry.primitives import face_areas

    return float(np.sqrt(face_areas(V, F).sum()))


def nearest(points: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest vertex of V (n,3) to each point (p,3), Euclidean: (ids (p,) int64, distances (p,) float)."""
    from scipy.spatial import cKDTree

    d, ids = cKDTree(V).query(points)
    return np.asarray(ids, np.int64), np.asarray(d, np.float64)


def true_map(V_template_new: np.ndarray, V_template: np.ndarray, V_pose: np.ndarray, V_pose_new: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The true map remeshed template -> remeshed pose through the original meshes (vertex o <-> vertex o).

    Args: the remeshed template's vertices (n_s,3), the original template's and pose's (n,3, same ids), the
    remeshed pose's (n_t,3).
    Returns: truth (n_s,) int64 remeshed pose vertex of each remeshed template vertex; the two snap distances
    (n_s,) float each (template vertex -> original template vertex, original pose vertex -> remeshed pose
    vertex), not normalised.
    """
    o, d_template = nearest(V_template_new, V_template)
    truth, d_pose = nearest(V_pose[o], V_pose_new)
    return truth, d_template, d_pose


def closest_surface_points(V_template_new: np.ndarray, V_template: np.ndarray, F_template: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Closest point of the original template's surface (V_template (n,3), F_template (m,3)) to each remeshed
    template vertex (n_s,3), Open3D's closest-point query: its triangle's corners (n_s,3) int64 (original vertex
    ids) and barycentric coordinates (n_s,3) float."""
    from corr_core.open3d_loader import load_open3d

    o3d = load_open3d()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(V_template, np.float32)),
                        o3d.core.Tensor(np.asarray(F_template, np.uint32)))
    hit = scene.compute_closest_points(o3d.core.Tensor(np.asarray(V_template_new, np.float32)))
    corners = np.asarray(F_template, np.int64)[hit["primitive_ids"].numpy().astype(np.int64)]
    u, v = hit["primitive_uvs"].numpy().astype(np.float64).T
    return corners, np.stack([1 - u - v, u, v], axis=1)


def exact_map(V_template_new: np.ndarray, V_template: np.ndarray, F_template: np.ndarray, V_pose: np.ndarray,
              V_pose_new: np.ndarray) -> np.ndarray:
    """Remeshed template vertices (n_s,3) -> closest points on the original template (V_template (n,3),
    F_template (m,3)) -> the same barycentric points of the original pose (V_pose (n,3), same triangles) ->
    nearest remeshed pose vertex of V_pose_new (n_t,3): (n_s,) int64. ``carried_map`` of the identity map."""
    return carried_map(V_template_new, V_template, F_template, np.arange(len(V_template)), V_pose, V_pose_new)


def carried_map(V_template_new: np.ndarray, V_template: np.ndarray, F_template: np.ndarray, p2p: np.ndarray,
                V_pose: np.ndarray, V_pose_new: np.ndarray) -> np.ndarray:
    """A map between the original meshes carried to the remeshed ones: each remeshed template vertex (n_s,3) ->
    its closest point on the original template (V_template (n,3), F_template (m,3)) -> the barycentric
    combination of the images ``p2p`` (n,) int (original template vertex -> original pose vertex of V_pose
    (n_p,3)) of that triangle's corners -> the nearest remeshed pose vertex of V_pose_new (n_t,3): (n_s,) int64.

    It scores what a map exactly as accurate as ``p2p`` is on the original meshes scores on these meshes,
    whose coarser vertices and snapped ground truth add their own error (the identity map gives ``exact_map``)."""
    corners, bary = closest_surface_points(V_template_new, V_template, F_template)
    return carry(corners, bary, p2p, V_pose, V_pose_new)


def carry(corners: np.ndarray, bary: np.ndarray, p2p: np.ndarray, V_pose: np.ndarray, V_pose_new: np.ndarray
          ) -> np.ndarray:
    """``carried_map`` from the template's closest surface points (``closest_surface_points``: corners (n_s,3)
    int original vertex ids, barycentric coordinates (n_s,3) float), which do not depend on the pose: (n_s,)
    int64 remeshed pose vertex ids."""
    p2p = np.asarray(p2p, np.int64)
    images = p2p[corners]
    if (images < 0).any() or (images >= len(V_pose)).any():
        raise ValueError(f"carried_map: the map sends vertices the remeshed template needs to no pose vertex "
                         f"(ids outside 0..{len(V_pose) - 1})")
    points = np.einsum("pk,pkd->pd", bary, np.asarray(V_pose, np.float64)[images])
    return nearest(points, V_pose_new)[0]


def floor_errors(out: str, data: str, names: list[str]) -> dict:
    """{pose: mean error of ``exact_map`` against ground_truth/<pose>.txt} (geodesic on the remeshed pose /
    sqrt(its area), at the 2,000 farthest-point template vertices bench/correspondence.py evaluates), printed."""
    return remeshed_errors(out, data, names)["exact"]


def remeshed_errors(out: str, data: str, names: list[str], maps_dir: str | None = None) -> dict:
    """Mean errors on the remeshed set ``out`` (of the course set ``data``) against ground_truth/<pose>.txt,
    measured as bench/correspondence.py measures (geodesic on the remeshed pose / sqrt(its area) at the 2,000
    farthest-point template vertices), printed per pose and on average: of ``exact_map`` ("exact"), and with
    ``maps_dir`` of every map between the original meshes in maps_dir/<method>/<pose>.txt (as
    ``bench/correspondence.py --save-maps`` writes them) carried by ``carried_map`` (label: the method).

    Returns {label: {pose: mean error}} (a method without a file for a pose is left out there)."""
    from corr_core.correspondence.dense import basis as dense_basis
    from corr_core.correspondence.dense import measures
    from corr_core.geometry.mesh_io import load_mesh

    Vs, Fs = load_mesh(os.path.join(data, "meshes", "template", "mesh000.obj"))
    Vs2, Fs2 = load_mesh(os.path.join(out, "meshes", "template", "mesh000.obj"))
    S = dense_basis.mesh_basis(Vs2, Fs2, k=100)
    vertices = S.vids[S.samples[:2000]]
    corners, bary = closest_surface_points(Vs2, Vs, Fs)          # the same for every pose and every map
    identity = np.arange(len(Vs))
    methods = sorted(m for m in os.listdir(maps_dir) if os.path.isdir(os.path.join(maps_dir, m))) if maps_dir else []
    means: dict = {"exact": {}, **{m: {} for m in methods}}
    for name in names:
        Vt, _ = load_mesh(os.path.join(data, "meshes", "test", f"{name}.obj"))
        Vt2, Ft2 = load_mesh(os.path.join(out, "meshes", "test", f"{name}.obj"))
        truth = np.loadtxt(os.path.join(out, "ground_truth", f"{name}.txt"), dtype=np.int64)
        maps = {"exact": carry(corners, bary, identity, Vt, Vt2)}            # exact_map
        for m in methods:
            path = os.path.join(maps_dir, m, f"{name}.txt")
            if os.path.isfile(path):
                p2p = np.loadtxt(path, dtype=np.int64)
                if p2p.shape != (len(Vs),):
                    raise SystemExit(f"{path}: {p2p.shape[0]} ids, the original template has {len(Vs)} vertices: "
                                     f"not a map of {data}")
                maps[m] = carry(corners, bary, p2p, Vt, Vt2)                  # carried_map
        errs = measures.dense_errors(Vt2, Ft2, maps, truth, vertices=vertices)
        for label, e in errs.items():
            means[label][name] = float(e.mean())
        print(f"{name:<8} " + "  ".join(f"{label if label != 'exact' else 'exact map'}: mean {e.mean():.5f}, "
                                        f"within 0.05 {np.mean(e <= 0.05):.3f}" for label, e in errs.items()),
              flush=True)
    for label, per_pose in means.items():
        if not per_pose:
            print(f"{'poses':<8} {label}: no map file for these poses in {maps_dir}/{label}/")
            continue
        what = "exact map" if label == "exact" else f"{label} carried"
        print(f"{'poses':<8} {what} against the ground truth: mean {np.mean(list(per_pose.values())):.5f} "
              f"({len(per_pose)} poses)")
    return means


def against_lines(carried: dict, runs: list[str]) -> list[str]:
    """Lines comparing each method's mean error in ``bench/correspondence.py --json`` runs ``runs`` (their per-pose
    ``mean_error``: on the remeshed set, its own maps there; on the original meshes, the maps that were carried)
    with its carried mean error (``remeshed_errors``' result {method: {pose: mean}}), over the poses both have, as
    ratios both ways."""
    lines = []
    for path in runs:
        with open(path) as fh:
            pairs = {row["mesh"]: row for row in json.load(fh)["pairs"]}
        for method, per_pose in carried.items():
            poses = [p for p in per_pose if p in pairs and method in pairs[p]]
            if method == "exact" or not poses:
                continue
            own = float(np.mean([pairs[p][method]["mean_error"] for p in poses]))
            ref = float(np.mean([per_pose[p] for p in poses]))
            lines.append(f"{method}: {own:.5f} in {os.path.basename(path)} / carried {ref:.5f} = x{own / ref:.3f}, "
                         f"carried / run x{ref / own:.3f} ({len(poses)} poses)")
    return lines


def snapped_landmarks(ids: np.ndarray, V: np.ndarray, V_new: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Landmark vertices ids (L,) of V (n,3) moved to the nearest vertices of V_new (n2,3): (ids (L,), distances
    (L,)). Raises ValueError when two landmarks land on one vertex (``what`` names the mesh)."""
    new, d = nearest(V[np.asarray(ids, np.int64)], V_new)
    if len(np.unique(new)) != len(new):
        raise ValueError(f"{what}: two landmarks snap to the same remeshed vertex; draw another --seed")
    return new, d


def prepare_out(out: str) -> None:
    """Create ``out`` (with a marker file); refuse an existing non-empty folder without the marker, and empty
    one with it (a previous run of this script) before writing again."""
    if os.path.abspath(out).startswith(ROOT + os.sep):
        raise SystemExit(f"{out} is inside the repository ({ROOT}): no data is kept there; choose another --out")
    if os.path.isdir(out) and os.listdir(out):
        if not os.path.isfile(os.path.join(out, MARKER)):
            raise SystemExit(f"{out} exists, is not empty and was not written by {os.path.basename(__file__)}: "
                             "choose another --out")
        shutil.rmtree(out)
    os.makedirs(out, exist_ok=True)
    open(os.path.join(out, MARKER), "w").close()


def write_truth(path: str, truth: np.ndarray) -> None:
    """``ground_truth/<mesh>.txt``: one 0-based target vertex id per template vertex, a line each."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as fh:
        fh.write("".join(f"{int(t)}\n" for t in truth))


def remesh_set(data: str, out: str, seed: int = 0, poses: int | None = None) -> dict:
    """Write the remeshed copy of the course set ``data`` to ``out`` (see the module docstring), printing the
    snap errors. ``poses``: only the first N test meshes. Returns {mesh: {"n_vertices", "n_faces",
    "landmark_snap": (mean, max), and "template_snap" (mesh000) or "pose_snap" (the poses): (mean, max)}},
    distances / sqrt(the remeshed mesh's area)."""
    from corr_core.correspondence.landmarks import read_landmarks, write_landmarks
    from corr_core.correspondence.measures import numbering_problem
    from corr_core.geometry.mesh_io import load_mesh, save_obj

    rng = np.random.default_rng(seed)
    tests = sorted(glob.glob(os.path.join(data, "meshes", "test", "*.obj")))[:poses]
    Vs, Fs = load_mesh(os.path.join(data, "meshes", "template", "mesh000.obj"))
    lm_ids, lm_names = read_landmarks(os.path.join(data, "landmark_vids.txt"), n_vertices=len(Vs))
    sp_ids, sp_names = read_landmarks(os.path.join(data, "sparse_landmark_vids.txt"), n_vertices=len(Vs))
    prepare_out(out)
    for sub in ("meshes/template", "meshes/test", "landmarks", "ground_truth"):
        os.makedirs(os.path.join(out, sub), exist_ok=True)

    Vs2, Fs2 = shuffle_vertices(*decimate(Vs, Fs, rng.integers(MIN_VERTICES, MAX_VERTICES + 1)), rng)
    save_obj(os.path.join(out, "meshes", "template", "mesh000.obj"), Vs2, Fs2)
    tpl_lms, d_lm = snapped_landmarks(lm_ids, Vs, Vs2, "mesh000")
    by_name = dict(zip(lm_names, tpl_lms.tolist()))
    write_landmarks(os.path.join(out, "landmark_vids.txt"), tpl_lms, lm_names)
    write_landmarks(os.path.join(out, "sparse_landmark_vids.txt"), [by_name[n] for n in sp_names], sp_names)
    write_landmarks(os.path.join(out, "landmarks", "mesh000.txt"), tpl_lms, lm_names)
    scale_s = sqrt_area(Vs2, Fs2)
    print(f"template and {len(tests)} poses, decimated each on its own to {MIN_VERTICES}..{MAX_VERTICES} vertices "
          f"(seed {seed}); snap distances / sqrt(remeshed area), mean and max:")
    print(f"{'mesh':<8}{'verts':>7}{'tpl mean':>10}{'tpl max':>9}{'pose mean':>10}{'pose max':>9}"
          f"{'lm mean':>10}{'lm max':>9}")
    d_tpl = nearest(Vs2, Vs)[1] / scale_s      # the same snap for every pose (``true_map``'s first step)
    info = {"mesh000": {"n_vertices": len(Vs2), "n_faces": len(Fs2), "template_snap": _stats(d_tpl),
                        "landmark_snap": _stats(d_lm / scale_s)}}
    print(f"{'mesh000':<8}{len(Vs2):>7}{d_tpl.mean():>10.5f}{d_tpl.max():>9.5f}{'':>19}"
          f"{d_lm.mean() / scale_s:>10.5f}{d_lm.max() / scale_s:>9.5f}")

    for path in tests:
        name = os.path.splitext(os.path.basename(path))[0]
        Vt, Ft = load_mesh(path)
        Vt2, Ft2 = shuffle_vertices(*decimate(Vt, Ft, rng.integers(MIN_VERTICES, MAX_VERTICES + 1)), rng)
        if numbering_problem(Fs2, Ft2) is None:
            raise RuntimeError(f"{name}: remeshed with the template's triangles")
        save_obj(os.path.join(out, "meshes", "test", f"{name}.obj"), Vt2, Ft2)
        truth, _, d_pose = true_map(Vs2, Vs, Vt, Vt2)
        write_truth(os.path.join(out, "ground_truth", f"{name}.txt"), truth)
        own, d_lm = snapped_landmarks(lm_ids, Vt, Vt2, name)
        write_landmarks(os.path.join(out, "landmarks", f"{name}.txt"), own, lm_names)
        parts = {"pose_snap": d_pose / sqrt_area(Vt2, Ft2), "landmark_snap": d_lm / sqrt_area(Vt2, Ft2)}
        info[name] = {"n_vertices": len(Vt2), "n_faces": len(Ft2), **{k: _stats(v) for k, v in parts.items()}}
        print(f"{name:<8}{len(Vt2):>7}{'':>19}" + "".join(f"{d.mean():>10.5f}{d.max():>9.5f}" for d in parts.values()),
              flush=True)
    _print_means(info)
    return info


def _stats(d: np.ndarray) -> tuple[float, float]:
    """(mean, max) of distances (p,) float."""
    return float(np.mean(d)), float(np.max(d))


def _print_means(info: dict) -> None:
    """Print the poses' mean of each snap's per-mesh mean, the largest max and the mean vertex count."""
    poses = [v for k, v in info.items() if k != "mesh000"]
    if not poses:
        return
    cells = "".join(f"{np.mean([p[k][0] for p in poses]):>10.5f}{max(p[k][1] for p in poses):>9.5f}"
                    for k in ("pose_snap", "landmark_snap"))
    print(f"{'poses':<8}{int(np.mean([p['n_vertices'] for p in poses])):>7}{'':>19}{cells}   (mean of the means, "
          "largest max; vertices: mean)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=DEFAULT_DATA, help="course scape/ folder")
    ap.add_argument("--out", default="/tmp/scape_remeshed", help="output folder (outside the repository)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--poses", type=int, default=None, help="only the first N test meshes")
    ap.add_argument("--floor", action="store_true", help="also the error of the exact map (see above)")
    ap.add_argument("--carry", default=None, metavar="MAPS",
                    help="do not remesh: score the maps of the original meshes in MAPS/<method>/<pose>.txt "
                         "(bench/correspondence.py --save-maps) carried to the existing set --out (see above)")
    ap.add_argument("--against", default=None, nargs="+", metavar="JSON",
                    help="with --carry: each method's mean error in these bench/correspondence.py --json runs (on "
                         "the remeshed set, or the original one) against its carried mean error (shared poses)")
    args = ap.parse_args(argv)
    if args.against and not args.carry:
        ap.error("--against needs --carry")
    if args.carry:
        if not os.path.isdir(args.carry):
            raise SystemExit(f"{args.carry}: no such folder of maps (bench/correspondence.py --save-maps writes one)")
        if not os.path.isfile(os.path.join(args.out, MARKER)):
            raise SystemExit(f"{args.out}: no remeshed set written by {os.path.basename(__file__)}; run it without "
                             "--carry first")
        names = sorted(os.path.splitext(f)[0] for f in os.listdir(os.path.join(args.out, "ground_truth")))
        means = remeshed_errors(args.out, args.data, names[:args.poses], args.carry)
        for line in against_lines(means, args.against or []):
            print(line)
        return 0
    info = remesh_set(args.data, args.out, args.seed, args.poses)
    if args.floor:
        floor_errors(args.out, args.data, [k for k in info if k != "mesh000"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
