"""The dense maps' two kinds of nearest-neighbour search, each against its plain version, on the searches an
automatic map really makes:

- spectral: the searches over every target vertex (ZoomOut's last iterations, its final match), brute force
  against the search by cells (``fmaps.nearest_rows(cells=...)``, for the default cells of
  ``MeshBasis.vertex_cells`` and every --centres x --regions setting);
- vertices: the 3-D nearest-vertex queries of the refinement (patch ICP, normal-compatible nearest vertices,
  neighbourhoods, the registration's read-back), scipy's ``cKDTree`` against ``nearest.PointTree`` (pykdtree).

    python bench/dense_searches.py [--seeds 0-1] [--poses 3] [--data SCAPE_FOLDER --pairs 2]
                                   [--centres 1000] [--regions 64]       (e.g. --centres 2000,1000,700,500)

Every automatic map (``dense_map``, nothing given on the target) of the generated bodies of each seed (other
people, poses 1..--poses, never the course poses) -- and, with ``--data``, of the first ``--pairs`` course-layout
targets -- is made once while its searches are recorded. Each recorded search is then timed (CPU seconds, one
thread) both ways and the answers compared. Prints the mean milliseconds per search, the ratio to the plain
version measured in the same run, and how many answers differ (must be 0).
"""
from __future__ import annotations

import argparse
import glob
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import one_blas_thread  # noqa: E402

one_blas_thread()

import numpy as np  # noqa: E402


def recorded_searches(V_s, F_s, S, targets, k_init: int) -> tuple[list, list]:
    """The searches of the automatic maps to ``targets`` (name, V, F): spectral [(target basis, queries (q,k)
    float32, points (n_t,k) float32)] (``fmaps.nearest_rows`` called with cells) and vertices [(points (n,3),
    queries (q,3), k)] (``nearest.PointTree.query``)."""
    from corr_core.correspondence.dense import basis, dense_map, fmaps, nearest

    spectral, vertices, current = [], [], {}
    real_rows, real_query = fmaps.nearest_rows, nearest.PointTree.query

    def spy_rows(queries, points, *, chunk=256, cells=None):
        if cells is not None:
            spectral.append((current["T"], np.array(queries, dtype=np.float32), np.array(points, dtype=np.float32)))
        return real_rows(queries, points, chunk=chunk, cells=cells)

    def spy_query(tree, P, *, k=1):
        vertices.append((tree.points, np.array(P, dtype=np.float64), k))
        return real_query(tree, P, k=k)

    fmaps.nearest_rows, nearest.PointTree.query = spy_rows, spy_query
    try:
        for name, V, F in targets:
            current["T"] = basis.mesh_basis(V, F, k=S.evecs.shape[1], n_samples=len(S.samples), name=name)
            dense_map(V_s, F_s, V, F, k=S.evecs.shape[1], k_init=k_init, basis_template=S,
                      basis_target=current["T"])
    finally:
        fmaps.nearest_rows, nearest.PointTree.query = real_rows, real_query
    return spectral, vertices


def brute_force(searches) -> tuple[float, list]:
    """(mean CPU ms per search, the answers) of the brute force over the recorded spectral searches."""
    from corr_core.correspondence.dense import fmaps

    seconds, answers = 0.0, []
    for _, queries, points in searches:
        t0 = time.process_time()
        answers.append(fmaps.nearest_rows(queries, points))
        seconds += time.process_time() - t0
    return 1000.0 * seconds / max(len(searches), 1), answers


def time_searches(searches, brute_answers: list, centres: int | None, regions: int | None) -> tuple[float, int]:
    """(mean CPU ms per search, answers differing from ``brute_answers``) with these cells (None: ``vertex_cells``'
    defaults)."""
    from corr_core.correspondence.dense import fmaps

    seconds, differ = 0.0, 0
    for (T, queries, points), brute in zip(searches, brute_answers):
        cells = T.vertex_cells(centres, regions)
        t0 = time.process_time()
        found = fmaps.nearest_rows(queries, points, cells=cells)
        seconds += time.process_time() - t0
        differ += int((found != brute).sum())
    return 1000.0 * seconds / max(len(searches), 1), differ


def time_vertex_queries(queries: list) -> tuple[float, float, int]:
    """(mean CPU ms per query batch with cKDTree, with ``PointTree``, answers differing) over the recorded 3-D
    queries [(points, P, k)]; each tree is built once per point set, outside the timing."""
    from scipy.spatial import cKDTree

    from corr_core.correspondence.dense.nearest import PointTree

    trees = {}
    seconds, differ = np.zeros(2), 0
    for points, P, k in queries:
        if id(points) not in trees:
            trees[id(points)] = (cKDTree(points), PointTree(points))
        answers = []
        for i, tree in enumerate(trees[id(points)]):
            t0 = time.process_time()
            answers.append(tree.query(P, k=k))
            seconds[i] += time.process_time() - t0
        (d0, i0), (d1, i1) = answers
        differ += int((np.asarray(i0) != np.asarray(i1)).sum() + (d0 != d1).sum())
    ms = 1000.0 * seconds / max(len(queries), 1)
    return float(ms[0]), float(ms[1]), differ


def generated(seeds: list[int], poses: int, work: str):
    """(label, template V, F, basis, [(name, V, F)], k_init) per seed: generated other bodies, poses 1..poses, at
    the settings of the generated-data benchmarks (``bench.dense_hypotheses.SETTINGS``)."""
    from bench.dense_hypotheses import SETTINGS, generated_targets, generated_template
    from corr_core.geometry.mesh_io import load_mesh

    for seed in seeds:
        root, _, S = generated_template(work, seed, poses, decimated=False)
        V_s, F_s = load_mesh(os.path.join(root, "meshes", "template", "mesh000.obj"))
        yield (f"seed {seed}", V_s, F_s, S, [(n, V, F) for n, V, F, _ in generated_targets(root, False)],
               SETTINGS["k_init"])


def course(data: str, pairs: int):
    """The course-layout folder's template and first ``pairs`` targets, as ``generated`` (``dense_map``'s
    defaults)."""
    from corr_core.correspondence.dense import basis
    from corr_core.geometry.mesh_io import load_mesh

    V_s, F_s = load_mesh(os.path.join(data, "meshes", "template", "mesh000.obj"))
    S = basis.mesh_basis(V_s, F_s, k=100, name="template")
    S.sample_distances(300)
    tests = sorted(glob.glob(os.path.join(data, "meshes", "test", "*.obj")))[:pairs]
    yield os.path.basename(os.path.normpath(data)), V_s, F_s, S, [
        (os.path.splitext(os.path.basename(p))[0], *load_mesh(p)) for p in tests], 40


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="0-1", help="generated seeds (other bodies), e.g. 0-1 or 0,3; '' for none")
    ap.add_argument("--poses", type=int, default=3)
    ap.add_argument("--data", default=None, help="also a course-layout folder (meshes/template, meshes/test)")
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--centres", default="1000", help="spectral cells' centres to time besides the default")
    ap.add_argument("--regions", default="64")
    ap.add_argument("--work", default=None, help="folder for the generated data (default: a temporary one)")
    args = ap.parse_args(argv)
    from bench.dense_hypotheses import seed_range

    sets = []
    with tempfile.TemporaryDirectory() as tmp:
        if args.seeds:
            sets += list(generated(seed_range(args.seeds), args.poses, args.work or tmp))
        if args.data:
            sets += list(course(args.data, args.pairs))
        grid = [(c, r) for c in seed_range(args.centres) for r in seed_range(args.regions)]
        for label, V_s, F_s, S, targets, k_init in sets:
            searches, vertex_queries = recorded_searches(V_s, F_s, S, targets, k_init)
            n_t = int(np.mean([len(p) for _, _, p in searches]))
            brute, brute_answers = brute_force(searches)
            print(f"{label}: {len(searches)} all-vertex searches of {len(targets)} automatic maps, "
                  f"{searches[0][1].shape[0]} queries among {n_t} target vertices (mean); brute force "
                  f"{brute:.1f} ms per search", flush=True)
            for centres, regions in [(None, None)] + grid:
                ms, differ = time_searches(searches, brute_answers, centres, regions)
                setting = "default (MeshBasis.vertex_cells)" if centres is None else \
                    f"{centres:5d} centres {regions:4d} regions"
                print(f"  cells {setting}: {ms:6.1f} ms  x{ms / brute:.3f} of the "
                      f"brute force  answers differing: {differ}", flush=True)
            plain, fast, differ = time_vertex_queries(vertex_queries)
            n_q = int(np.mean([len(P) for _, P, _ in vertex_queries]))
            print(f"  vertices: {len(vertex_queries)} nearest-vertex query batches ({n_q} points each, mean): "
                  f"cKDTree {plain:.2f} ms, PointTree {fast:.2f} ms per batch, x{fast / plain:.3f}  answers "
                  f"differing: {differ}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
