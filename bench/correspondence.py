"""Dense correspondence on the course SCAPE data: the project's dense maps against pyFM, in one run.

Template meshes/template/mesh000.obj -> each of meshes/test/*.obj. Ground truth: ``ground_truth/<mesh>.txt``
when present (one target vertex id per template vertex, a line each, 0-based; e.g. the remeshed set of
``bench/remesh_scape.py``), else vertex i <-> vertex i (the course meshes share their triangles). The target's
landmarks: ``landmarks/<mesh>.txt`` when present (its own ids, ``vid,Name``, matched to the template's by name),
else the template's ids of landmark_vids.txt.
Inputs used by every method: the two meshes; ``dense_sparse`` and pyFM "5 points" also the 5 sparse landmarks
(the names in sparse_landmark_vids.txt: its ids on the template, the target's own ids of those names on the
target); ``dense_auto`` and pyFM "none" no point on the target.
The 20 landmarks are used only to *evaluate* the transfer; uniform_sample_vids.txt is never read.

Methods:
  pyfm_none    pyFM 1.3 (pip ``pyfmaps``): WKS (100 energies, every 5th as descriptor) functional map 35x35 with the
               orientation term (w_descr 1, w_lap 0.1, w_dcomm 1, w_orient 1), ZoomOut on all vertices to 115
               (16 steps of 5); the point map of the ZoomOut map (pyFM 1.3 returns it without storing it)
  pyfm_5pts    the same with the 5 sparse landmarks as landmark descriptors
  dense_sparse corr_core.correspondence.dense with the 5 sparse landmarks given on both meshes; with dense_auto
               also run, its map is the ``alternative`` (kept when it keeps the points and is less distorted,
               as the pipelines do); dense_sparse's seconds leave out dense_auto's own
  dense_auto   corr_core.correspondence.dense, automatic (nothing given on the target)

Measures (target surface, heat-method geodesics, / sqrt(target area)): dense mean error over ``--eval-vertices``
farthest-point template vertices, fraction within 0.05 / 0.10 / 0.25, landmark accuracy (a transferred landmark is
right when its nearest true landmark has its name), landmark transfer error, seconds per pair. CPU seconds (time.process_time) per pair
includes the target's own per-mesh work (eigenpairs etc.); the template's is done once for every method
(pyFM: its template TriMesh is processed once and reused) and reported separately. Every method runs on one
BLAS/OpenMP thread (set at import), so the seconds count work, and the summary prints each project method's
seconds over each pyFM mode's.

The summary also lists the flipped targets (landmark accuracy < 0.5: a mirrored or turned map) of each method.

Run:  python bench/correspondence.py [--data SCAPE] [--pairs N] [--json OUT]
                                     [--methods pyfm_none,pyfm_5pts,dense_sparse,dense_auto] [--refine PLAN]
                                     [--second-opinion]
                                     [--save-maps DIR]
          (--save-maps: every method's map as DIR/<method>/<mesh>.txt, one target vertex id (0-based) a line per
          template vertex, e.g. for ``bench/remesh_scape.py --carry DIR``)
      python bench/correspondence.py --summarize OUT.json [OUT2.json ...] [--relative-to BASE.json ...]
          (the table of saved, possibly partial, runs; several files: their methods side by side on the pairs they
          share, e.g. the project's methods and pyFM run one after the other, the CPU-time ratios then compare two
          runs; --relative-to: each method's means against another set of runs, e.g. the remeshed set against
          the course meshes)
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench._env import SCAPE as DEFAULT_DATA, one_blas_thread  # noqa: E402

# One BLAS/OpenMP thread for every method, set before numpy is imported when run as a script (main() also caps
# an already loaded BLAS; importing this module leaves the environment alone).
if __name__ == "__main__":
    one_blas_thread()

import numpy as np  # noqa: E402
METHODS = ("pyfm_none", "pyfm_5pts", "dense_sparse", "dense_auto")


def _pyfm_template(path: str, k: int = 120):
    from pyFM.mesh import TriMesh

    return TriMesh(path, area_normalize=True, center=True).process(k=k, intrinsic=False, verbose=False)


def run_pyfm(template_mesh, target_path: str, landmarks=None) -> np.ndarray:
    """The pyFM recipe of docs/dense.md; returns (n_template,) target vertex ids.

    landmarks: None, or (p, 2) int pairs (template vertex id, target vertex id) of corresponding points.
    """
    from pyFM.functional import FunctionalMapping
    from pyFM.mesh import TriMesh

    target = TriMesh(target_path, area_normalize=True, center=True)
    model = FunctionalMapping(target, template_mesh)
    # pyFM's (p, 2) landmarks: column 0 on its mesh1 (the target), column 1 on its mesh2 (the template)
    lm = None if landmarks is None else np.asarray(landmarks, dtype=np.int64)[:, ::-1].copy()
    model.preprocess(n_descr=100, descr_type="WKS", landmarks=lm, subsample_step=5, k_process=120,
                     verbose=False)
    model.fit(K=(35, 35), w_descr=1, w_lap=0.1, w_dcomm=1, w_orient=1, verbose=False)
    # pyFM 1.3 returns the refined map and does not store it: convert *that* one (get_p2p() alone would use the
    # 35x35 map of fit())
    C_zoomout = model.zoomout_refine(nit=16, step=5, verbose=False)
    return np.asarray(model.get_p2p(FM=C_zoomout), dtype=np.int64)   # p2p_21: template vertex -> target vertex


def scape_layout(data: str, pairs: int | None = None) -> tuple[str, list[str]] | None:
    """The template's path and the first ``pairs`` (None: all) test meshes' paths, sorted, of a folder in the
    course SCAPE layout (``meshes/template/mesh000.obj``, ``meshes/test/*.obj``); None, with a line on stderr
    naming the folder, when either is missing."""
    template = os.path.join(data, "meshes", "template", "mesh000.obj")
    tests = sorted(glob.glob(os.path.join(data, "meshes", "test", "*.obj")))[:pairs]
    if not os.path.isfile(template) or not tests:
        print(f"no SCAPE data under {data} (expected meshes/template/mesh000.obj and meshes/test/*.obj)",
              file=sys.stderr)
        return None
    return template, tests


def checked_layout(ap, data: str, pairs: int) -> tuple[str, list[str]] | None:
    """``scape_layout(data, pairs)`` for a bench's ``--data`` and ``--pairs`` (``ap``: its ArgumentParser, whose
    ``error`` exits when ``pairs`` < 1)."""
    if pairs < 1:
        ap.error(f"--pairs must be >= 1, got {pairs}")
    return scape_layout(data, pairs)


def read_template(data: str, path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, list, list]:
    """The template mesh at ``path`` and the landmark files of the folder ``data`` (course SCAPE layout): V (n,3)
    float, F (m,3) int, the landmark ids (L,) int and names, and the names of the sparse landmarks."""
    from corr_core.correspondence.landmarks import read_landmarks
    from corr_core.geometry.mesh_io import load_mesh

    V, F = load_mesh(path)
    ids, names = read_landmarks(os.path.join(data, "landmark_vids.txt"), n_vertices=len(V))
    _, sparse_names = read_landmarks(os.path.join(data, "sparse_landmark_vids.txt"), n_vertices=len(V))
    return V, F, ids, names, sparse_names


def true_map(data: str, name: str, n_template: int, n_target: int) -> tuple[np.ndarray, str]:
    """(n_template,) int64 true target vertex of each template vertex and its source: ``ground_truth/<name>.txt``
    under ``data`` when present ("file"), else vertex i <-> vertex i ("identity", the course layout: the same
    triangles). Raises ValueError naming the file when it does not hold n_template ids in 0..n_target-1, and
    when identity is assumed for meshes of different vertex counts."""
    path = os.path.join(data, "ground_truth", f"{name}.txt")
    if os.path.isfile(path):
        truth = np.loadtxt(path, dtype=np.int64, ndmin=1)
        if truth.shape != (n_template,) or truth.min() < 0 or truth.max() >= n_target:
            raise ValueError(f"{path}: must hold {n_template} target vertex ids (one per template vertex, a line "
                             f"each) in 0..{n_target - 1}; got {truth.size} ids in {truth.min()}..{truth.max()}")
        return truth, "file"
    if n_template != n_target:
        raise ValueError(f"{name}: {n_target} vertices, the template {n_template}, and no {path}: vertex i <-> "
                         "vertex i cannot be the ground truth; give the true map in that file")
    return np.arange(n_template, dtype=np.int64), "identity"


def target_landmarks(data: str, name: str, names: list[str], shared_ids: np.ndarray, n_target: int
                     ) -> tuple[np.ndarray, str]:
    """(L,) int64 the target's vertex ids of the landmarks ``names`` (the template's, in its order) and their
    source: its own ``landmarks/<name>.txt`` (``vid,Name``, matched by name; "own") when present, else the
    template's ids ``shared_ids`` (L,) ("shared", the course layout). Raises ValueError naming the file when a
    name is missing."""
    from corr_core.correspondence.landmarks import read_landmarks

    path = os.path.join(data, "landmarks", f"{name}.txt")
    if not os.path.isfile(path):
        return np.asarray(shared_ids, dtype=np.int64), "shared"
    ids, own_names = read_landmarks(path, n_vertices=n_target)
    by_name = dict(zip(own_names, ids.tolist()))
    missing = [n for n in names if n not in by_name]
    if missing:
        raise ValueError(f"{path}: lacks the landmarks {missing} of the template's landmark file")
    return np.asarray([by_name[n] for n in names], dtype=np.int64), "own"


def sparse_pairs(names: list[str], sparse_names: list[str], template_ids: np.ndarray, target_ids: np.ndarray
                 ) -> np.ndarray:
    """(p, 2) int64 (template id, target id) of the sparse landmarks ``sparse_names``, from the full lists
    ``names`` (L,) with their template ids (L,) and target ids (L,). Raises ValueError for a name not in names."""
    where = {n: i for i, n in enumerate(names)}
    missing = [n for n in sparse_names if n not in where]
    if missing:
        raise ValueError(f"sparse landmarks {missing} are not in the landmark list {names}")
    pos = np.array([where[n] for n in sparse_names], dtype=np.int64)
    return np.stack([np.asarray(template_ids)[pos], np.asarray(target_ids)[pos]], axis=1).astype(np.int64)


def pair_truth(data: str, name: str, names: list[str], template_ids: np.ndarray, sparse_names: list[str],
               n_template: int, n_target: int) -> dict:
    """What the pair template -> target ``name`` is measured against and given: {"truth": (n_template,) int
    true map, "landmarks": (L,) int the target's true landmarks (in the order of ``names``, the template's
    landmarks ``template_ids`` (L,)), "sparse": (p, 2) int (template id, target id) of the ``sparse_names``,
    "source": where truth and landmarks come from} (``true_map``, ``target_landmarks``)."""
    truth, truth_source = true_map(data, name, n_template, n_target)
    landmarks, lm_source = target_landmarks(data, name, names, template_ids, n_target)
    return {"truth": truth, "landmarks": landmarks, "source": f"{truth_source}, landmarks {lm_source}",
            "sparse": sparse_pairs(names, sparse_names, template_ids, landmarks)}


SUMMARY_KEYS = ("landmark_accuracy", "mean_error", "within_0.05", "within_0.10", "within_0.25", "landmark_error",
                "seconds")


def print_summary(rows: list, methods: list, template_seconds: dict, n_eval: int, template: str) -> dict:
    """Print the side-by-side table (means over the pairs) and return {method: {measure: mean}}."""
    summary = {m: {k: float(np.mean([r[m][k] for r in rows])) for k in SUMMARY_KEYS} for m in methods}
    print(f"\n{len(rows)} pairs, template {template}; errors: geodesic / sqrt(area) at {n_eval} farthest-point "
          "template vertices; seconds: CPU per pair (target's per-mesh work included); template set-up (once): "
          + ", ".join(f"{k} {v:.1f}s" for k, v in template_seconds.items()))
    print(f"{'method':<14}{'lm acc':>8}{'mean err':>10}{'<=0.05':>8}{'<=0.10':>8}{'<=0.25':>8}{'lm err':>8}"
          f"{'s/pair':>8}")
    for m, s in summary.items():
        print(f"{m:<14}{s['landmark_accuracy']:>8.4f}{s['mean_error']:>10.4f}{s['within_0.05']:>8.3f}"
              f"{s['within_0.10']:>8.3f}{s['within_0.25']:>8.3f}{s['landmark_error']:>8.4f}{s['seconds']:>8.1f}")
    for line in time_ratio_lines(summary):
        print(line)
    for line in flip_lines(rows, methods):
        print(line)
    return summary


def flip_lines(rows: list, methods: list, below: float = 0.5) -> list[str]:
    """One printable line per method: the targets whose landmark accuracy is below ``below`` (a flipped map:
    mirrored, turned or twisted), with that accuracy."""
    lines = [f"flipped targets (landmark accuracy < {below}):"]
    for m in methods:
        flips = [f"{r['mesh']} {r[m]['landmark_accuracy']:.2f}" for r in rows if r[m]["landmark_accuracy"] < below]
        lines.append(f"  {m}: {len(flips)}" + (f" ({', '.join(flips)})" if flips else ""))
    return lines


def time_ratios(summary: dict) -> dict:
    """{(project method, pyFM mode): project CPU seconds / pyFM CPU seconds per pair} (the target: <= 1/3)."""
    ours = [m for m in summary if not m.startswith("pyfm")]
    peers = [m for m in summary if m.startswith("pyfm")]
    return {(m, p): summary[m]["seconds"] / summary[p]["seconds"] for m in ours for p in peers
            if summary[p]["seconds"] > 0}


def time_ratio_lines(summary: dict) -> list[str]:
    """The CPU-time ratios of ``time_ratios`` as printable lines (none without both kinds of method)."""
    ratios = time_ratios(summary)
    if not ratios:
        return []
    return ["CPU time per pair, project / pyFM (target <= 0.333):"] + [
        f"  {m} / {p}: {r:.3f}{'' if r <= 1 / 3 else '  (above 1/3)'}" for (m, p), r in ratios.items()]


def merged_rows(runs: list[dict]) -> tuple[list, dict]:
    """The per-pair rows of several --json results side by side: (rows of the meshes every run has, each
    {"mesh", method: measures} with every run's methods; the template seconds of all runs, the first run's
    value kept for a key two runs share)."""
    by_mesh = [{r["mesh"]: r for r in run["pairs"]} for run in runs]
    meshes = [m for m in by_mesh[0] if all(m in b for b in by_mesh[1:])]
    rows = [{k: v for b in reversed(by_mesh) for k, v in b[m].items()} for m in meshes]
    template_seconds = {k: v for run in reversed(runs) for k, v in run.get("template_seconds", {}).items()}
    return rows, template_seconds


def relative_lines(summary: dict, base: dict, label: str) -> list[str]:
    """Printable lines: each method of ``summary`` (and of ``base``, both {method: {measure: mean}}) against
    ``base``: mean error and CPU seconds as ratios, landmark accuracy and the within-0.05 / 0.25 fractions as
    differences."""
    lines = [f"relative to {label} (ratio of mean error, of s/pair; difference of lm acc, <=0.05, <=0.25):"]
    for m in (m for m in summary if m in base):
        s, b = summary[m], base[m]
        diff = {k: s[k] - b[k] for k in ("landmark_accuracy", "within_0.05", "within_0.25")}
        lines.append(f"  {m:<13} mean err x{s['mean_error'] / b['mean_error']:.3f}  s/pair "
                     f"x{s['seconds'] / b['seconds']:.3f}  lm acc {diff['landmark_accuracy']:+.4f}  <=0.05 "
                     f"{diff['within_0.05']:+.3f}  <=0.25 {diff['within_0.25']:+.3f}")
    return lines


def load_runs(paths: list[str]) -> list[dict]:
    """The --json results files ``paths``, read."""
    runs = []
    for path in paths:
        with open(path) as fh:
            runs.append(json.load(fh))
    return runs


def summarize(paths: list[str], relative_to: list[str] | None = None) -> int:
    """Print the table of results files written with --json (also of interrupted runs: their finished pairs);
    several files are merged on the pairs they all have (``merged_rows``). ``relative_to``: results files of
    a baseline (e.g. the same methods on the same-triangulation data), compared method by method on the
    pairs' means (``relative_lines``)."""
    runs = load_runs(paths)
    rows, template_seconds = merged_rows(runs)
    if not rows:
        print(f"{', '.join(paths)}: no finished pair (in common)", file=sys.stderr)
        return 2
    methods = [m for m in rows[0] if m != "mesh"]
    print("pairs: " + " ".join(r["mesh"] for r in rows))
    for path, run in zip(paths, runs):
        print(f"{path}: data {run.get('data', '?')}, ground truth {run.get('truth', '?')}")
    summary = print_summary(rows, methods, template_seconds, runs[0].get("eval_vertices", 2000),
                            "meshes/template/mesh000.obj")
    if relative_to:
        base_rows, _ = merged_rows(load_runs(relative_to))
        base = {m: {k: float(np.mean([r[m][k] for r in base_rows])) for k in SUMMARY_KEYS}
                for m in base_rows[0] if m != "mesh"}
        for line in relative_lines(summary, base, ", ".join(relative_to)):
            print(line)
    return 0


def save_maps(folder: str, mesh: str, maps: dict) -> None:
    """Write each method's map {method: (n_s,) int target vertex ids} as folder/<method>/<mesh>.txt, one id a line
    (``numpy.loadtxt(..., dtype=int)`` reads it back)."""
    for method, p2p in maps.items():
        os.makedirs(os.path.join(folder, method), exist_ok=True)
        np.savetxt(os.path.join(folder, method, f"{mesh}.txt"), np.asarray(p2p, dtype=np.int64), fmt="%d")


def _limit_threads() -> None:
    """Cap BLAS/OpenMP pools at one thread even when numpy was loaded before this module (threadpoolctl, when
    installed; the environment variables set at import cover the normal ``python bench/correspondence.py``)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
    threadpool_limits(1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=DEFAULT_DATA, help="course scape/ folder")
    ap.add_argument("--pairs", type=int, default=None, help="only the first N test meshes")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--eval-vertices", type=int, default=2000, help="farthest-point template vertices evaluated")
    ap.add_argument("--refine", default=None, help="the dense methods' refinement plan (refine.refine_plan, e.g. "
                    "extrinsic+deform; default: dense_map's)")
    ap.add_argument("--refine-options", default=None, metavar="JSON",
                    help='the dense methods\' refine_options, e.g. \'{"deform": {"iterations": 6}}\'')
    ap.add_argument("--second-opinion", action="store_true",
                    help="dense_auto with dense_map(second_opinion=True) (refine.second_opinion)")
    ap.add_argument("--json", default=None, help="write per-pair and summary results here")
    ap.add_argument("--save-maps", default=None, metavar="DIR",
                    help="also write every map as DIR/<method>/<mesh>.txt (one target vertex id a line)")
    ap.add_argument("--summarize", default=None, nargs="+", metavar="JSON",
                    help="only print the table of --json files (several: merged on their common pairs)")
    ap.add_argument("--relative-to", default=None, nargs="+", metavar="JSON",
                    help="with --summarize: compare each method with these --json results (e.g. same-triangulation)")
    args = ap.parse_args(argv)
    if args.summarize:
        return summarize(args.summarize, args.relative_to)
    _limit_threads()

    from corr_core.correspondence.dense import basis as dense_basis
    from corr_core.correspondence.dense import dense_map, measures
    from corr_core.correspondence.dense.transfer import transfer_landmarks
    from corr_core.geometry.geodesic import GeodesicSolver
    from corr_core.geometry.mesh_io import load_mesh

    plan = {} if args.refine is None else {"refine": args.refine}
    if args.refine_options:
        plan["refine_options"] = json.loads(args.refine_options)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown:
        ap.error(f"unknown methods {unknown}; choose from {', '.join(METHODS)}")
    found = scape_layout(args.data, args.pairs)
    if found is None:
        return 2
    tpl_path, tests = found
    Vs, Fs, lm_ids, lm_names, sparse_names = read_template(args.data, tpl_path)

    t0 = time.process_time()
    S = dense_basis.mesh_basis(Vs, Fs, k=100, name=tpl_path)
    S.sample_distances(300)                     # template geodesics of the refinement's patches (once per template)
    template_seconds = {"dense": time.process_time() - t0}
    pyfm_template = None
    if any(m.startswith("pyfm") for m in methods):
        t0 = time.process_time()
        pyfm_template = _pyfm_template(tpl_path)
        template_seconds["pyfm"] = time.process_time() - t0
    eval_vertices = S.vids[S.samples[:args.eval_vertices]]        # original template ids

    sources = set()

    rows = []
    for path in tests:
        name = os.path.splitext(os.path.basename(path))[0]
        Vt, Ft = load_mesh(path)
        given = pair_truth(args.data, name, lm_names, lm_ids, sparse_names, len(Vs), len(Vt))
        sparse = given["sparse"]                                   # (5, 2) template id, target id
        sources.add(given["source"])
        maps, seconds = {}, {}
        for m in sorted(methods, key=lambda m: m == "dense_sparse"):     # dense_auto's map first: its alternative
            t0 = time.process_time()
            if m == "pyfm_none":
                maps[m] = run_pyfm(pyfm_template, path)
            elif m == "pyfm_5pts":
                maps[m] = run_pyfm(pyfm_template, path, landmarks=sparse)
            else:
                T = dense_basis.mesh_basis(Vt, Ft, k=100, name=path)
                if m == "dense_sparse":
                    maps[m] = dense_map(Vs, Fs, Vt, Ft, sparse[:, 0], sparse[:, 1], basis_template=S,
                                        basis_target=T, alternative=maps.get("dense_auto"), **plan)
                else:
                    maps[m] = dense_map(Vs, Fs, Vt, Ft, basis_template=S, basis_target=T,
                                        second_opinion=args.second_opinion, **plan)
            seconds[m] = time.process_time() - t0
        if args.save_maps:
            save_maps(args.save_maps, name, maps)
        solver = GeodesicSolver(Vt, Ft)
        errs = measures.dense_errors(Vt, Ft, maps, given["truth"], vertices=eval_vertices, solver=solver)
        row = {"mesh": name}
        for m in methods:
            placed = transfer_landmarks(maps[m], lm_ids)
            lm_err, nearest = measures.landmark_errors(Vt, Ft, placed, given["landmarks"], solver=solver)
            row[m] = {**measures.summary(errs[m]), "landmark_accuracy": measures.landmark_accuracy(nearest),
                      "landmark_error": float(lm_err.mean()), "seconds": seconds[m],
                      "kim_curve": measures.kim_curve(errs[m]).tolist()}
        rows.append(row)
        run = {"data": os.path.abspath(args.data), "truth": "; ".join(sorted(sources)),
               "eval_vertices": len(eval_vertices), "template_seconds": template_seconds}
        if args.json:                                          # per-pair results survive an interrupted run
            with open(args.json, "w") as fh:
                json.dump({**run, "pairs": rows}, fh, indent=1)
        print(name + "  " + "  ".join(f"{m}: {row[m]['mean_error']:.4f} acc {row[m]['landmark_accuracy']:.2f} "
                                      f"{row[m]['seconds']:.1f}s" for m in methods), flush=True)

    print(f"ground truth: {'; '.join(sorted(sources))}")
    summary = print_summary(rows, methods, template_seconds, len(eval_vertices),
                            os.path.relpath(tpl_path, args.data))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({**run, "summary": summary, "pairs": rows}, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
