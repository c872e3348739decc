"""Stage wiring for dense correspondence (every template vertex -> a target vertex) and landmark transfer.

Per mesh (cached, shared by both methods): ``corr.dense_basis`` (Laplace-Beltrami eigenpairs, vertex areas,
farthest-point samples; ``corr_core.correspondence.dense.mesh_basis``) as plain arrays.
Once: ``corr.dense_template`` -- the template's basis with its patch-centre geodesics and extremities (for every
target's tasks).
Per test mesh: ``corr.dense_init`` -- the initial map, ``mode`` "sparse" (the 5 sparse landmarks given on both
meshes: ``dense_sparse``) or "auto" (nothing given on the target: ``dense_auto``); ``corr.dense_refine`` -- the
full-resolution map and its pointwise refinement (its own stage: changing its params reruns only it and the
evaluation); ``corr.dense_measures`` -- errors against the ground truth, where there is one.
Once: ``corr.place_landmarks`` (the template's landmarks placed on every target, published as files), and the
summaries in ``corr.evaluate`` (``dense_reports``).

Ground truth of a test mesh: vertex i <-> vertex i when it has the template's triangles (its vertex count and
order alone never decide: ``landmark_sources.numbered_like_template``), else
``ground_truth/<mesh>.txt`` (one target vertex id per template vertex, a line each), else none (maps and placed
landmarks are still produced, without error numbers). Its true landmarks: ``landmarks/<mesh>.txt``, else the
shared landmark file on a mesh numbered like the template, else the ground-truth map applied to the template's.
"""
from __future__ import annotations

import os

import numpy as np

from corr_core import plotting
from corr_core.correspondence import dense, measures
from corr_core.correspondence.dense import measures as dense_measures_lib
from corr_core.correspondence.dense.basis import MeshBasis, map_to_local, map_to_original
from corr_core.correspondence.dense.refine import LOW_CONFIDENCE
from corr_core.correspondence.landmarks import read_landmarks, write_landmarks
from corr_core.geometry.geodesic import GeodesicSolver
from corr_core.geometry.intrinsic import IntrinsicMesh
from corr_core.geometry.mesh_io import save_ply
from corr_core.geometry.sampling import farthest_point_samples

from stages.registry import register

from .landmark_sources import mesh_landmarks, numbered_like_template, sparse_positions
from .skips import holds, is_skipped, skip_reason, skip_reasons, skipped

METHODS = ("dense_sparse", "dense_auto")
KIM_LABELS = {"mobius": "Möbius (best map)", "dense_sparse": "dense_sparse (5 points)",
              "dense_auto": "dense_auto (no points)"}


@register("corr.dense_basis", group="correspondence", fanout="item")
def dense_basis(mesh, *, k: int = 100, n_samples: int = 2000) -> dict:
    """Spectral basis of one mesh's largest component: ``MeshBasis.to_arrays()`` -- {"V", "F", "evals": (k,),
    "evecs": (n,k), "mass": (n,), "area", "samples": (n_samples,), "vids": (n,) original ids, "n_full"}."""
    return dense.mesh_basis(mesh["V"], mesh["F"], k=k, n_samples=n_samples, name=mesh["name"]).to_arrays()


@register("corr.dense_template", group="correspondence", fanout="once")
def dense_template(template_basis, *, n_patches: int = 300) -> dict:
    """What every target's tasks need of the template, computed once instead of once per target:
    ``corr.dense_basis``'s arrays plus "sample_distances" ((n_patches, n) float / sqrt(area): geodesics from the
    patch centres of ``refine_extrinsic``), "extremities" ((p,) int local ids: ``init.extremities``, the
    feature points of ``map_automatic``) and their geodesics ("point_distance_ids" / "point_distance_rows":
    ``MeshBasis.point_distances``)."""
    S = _basis(template_basis, "template")
    S.sample_distances(n_patches)
    dense.init.cached_extremities(S)
    return S.to_arrays()


def _which(mesh: dict) -> str:
    """The mesh's file, and its item when that is another name (for messages)."""
    item = mesh.get("item")
    return mesh["name"] + (f" (item {item})" if item and item != os.path.splitext(mesh["name"])[0] else "")


def _basis(arrays: dict, what: str) -> MeshBasis:
    return MeshBasis.from_arrays(arrays, source=f"corr.dense_basis of the {what}")


@register("corr.dense_init", group="correspondence", fanout="item")
def dense_init(template_basis, target_basis, template_mesh, target_mesh, landmarks, sparse_landmarks,
               landmark_files=None, *, mode: str = "auto", k_init: int = 40, k_end: int = 100,
               hypotheses: int | None = None) -> dict:
    """Initial map template -> target: a functional map refined by ZoomOut and the point map of the template
    samples. mode "sparse": from the sparse landmarks given on both meshes (a target without landmarks is
    skipped: ``skips.skipped(why)``); "auto": from nothing on the target (extremities, orientation-aware), with the
    next ranked maps too, for ``corr.dense_refine`` to choose from after refinement (``automatic_hypotheses``:
    how many is decided there when ``hypotheses`` is None -- the best two, more when they are close; an
    integer forces that many, e.g. 1 to time a single hypothesis).

    Returns {"C": (k_end, k_end) float, "p2p_samples": (s,) int local target ids, "mode": str}; auto also
    "k_init", "k_end" (for ``corr.dense_refine``'s second opinion, made as the sparse mode makes a map) and, with
    more than one hypothesis, "C_more": (h, k_end, k_end) and "p2p_samples_more": (h, s) (the others); sparse
    also "points": (2, L) int local ids of the given points (template row, target row).
    """
    if mode not in ("sparse", "auto"):
        raise ValueError(f"corr.dense_init: mode must be 'sparse' or 'auto', got {mode!r}")
    S, T = _basis(template_basis, "template"), _basis(target_basis, "target")
    if mode == "auto":
        try:
            (C, p2p), *more = dense.automatic_hypotheses(S, T, hypotheses, k_init=k_init, k_end=k_end)
        except ValueError as exc:  # name the files: the message alone does not say which mesh
            raise ValueError(f"{_which(target_mesh)} (template {_which(template_mesh)}): {exc}; give this mesh "
                             "sparse landmarks and use mode 'sparse', or leave it out") from None
        out = {"C": C, "p2p_samples": p2p, "mode": mode, "k_init": int(k_init), "k_end": int(k_end)}
        if more:
            out.update(C_more=np.asarray([c for c, _ in more]), p2p_samples_more=np.asarray([p for _, p in more]))
        return out
    target_ids, source = mesh_landmarks(target_mesh, landmarks, landmark_files, template_mesh)
    if target_ids is None:
        return skipped(f"{source} (dense_sparse needs the sparse landmarks on the target)")
    template_ids, _ = mesh_landmarks(template_mesh, landmarks, landmark_files, template_mesh)
    sparse = sparse_positions(landmarks, sparse_landmarks)
    C, p2p = dense.map_from_points(S, T, template_ids[sparse], target_ids[sparse], k_init=k_init, k_end=k_end)
    points = np.stack([S.to_local(template_ids[sparse], what="template point"),
                       T.to_local(target_ids[sparse], what="target point")])
    return {"C": C, "p2p_samples": p2p, "mode": mode, "points": points}


def _refine_plan(*, refine, n_patches: int, patch_size: int, rounds: int, icp_iterations: int,
                 stiffness: float) -> tuple:
    """``corr.dense_refine``'s params as typed refinement steps (``refine.refine_plan``; ValueError names a
    misspelt step or option)."""
    extrinsic = {"n_patches": n_patches, "patch_size": patch_size, "rounds": rounds, "icp_iterations": icp_iterations}
    return dense.refine_plan(refine, {"extrinsic": extrinsic, "deform": {"stiffness": stiffness},
                                      "settle": {"stiffness": stiffness}})


def _check_refine(*, second_opinion: bool = False, **params) -> None:
    """``corr.dense_refine``'s check when the pipeline is read: the refinement plan must name known steps."""
    try:
        _refine_plan(**params)
    except ValueError as e:
        raise ValueError(f"parameter 'refine' = {params['refine']!r}: {e}") from None


@register("corr.dense_refine", group="correspondence", fanout="item", validate=_check_refine)
def dense_refine(template_basis, target_basis, initial, alternative=None, *,
                 refine: str | list[str] = dense.DEFAULT_REFINE,
                 n_patches: int = 300,
                 patch_size: int = 64, rounds: int = 5, icp_iterations: int = 6, stiffness: float = 0.03,
                 second_opinion: bool = False) -> dict:
    """The dense map: the initial map upsampled to every template vertex (``upsample_spectral``), then refined
    (``refine``: steps of ``refine.refine_plan``, joined by "+" or as a list; "extrinsic+spectral+deform" =
    patch-wise rigid ICP, full-resolution ZoomOut, ARAP registration, as ``dense_map``; a step written "spectral?"
    is kept only where it lowers the distortion; "+settle" adds ARAP against the surface alone; "extrinsic",
    "spectral", "none", ...). ``n_patches`` ... ``icp_iterations``: ``refine_extrinsic``'s; ``stiffness``:
    ``refine_deform``'s and ``refine_settle``'s (the defaults of ``n_patches``, ``patch_size`` and ``stiffness``:
    swept by ``python bench/dense_constants.py --seeds 10-13``, docs/dense.md "Tuned constants"). Several initial
    hypotheses (``corr.dense_init`` with hypotheses > 1): each gets the first step (when that is the patch ICP, one
    surely beaten after its first round gets none of the others: ``refine.EARLY_DROP_MARGIN``), those surely
    beaten after a step (not the last) are dropped, the others are refined to the end and the least distorted result kept
    (``refine.refine_best``).
    Returns {"vertex_map": (n_template,) int target vertex id (original ids; -1 off the template's kept
    component), "hypothesis": index of the kept initial map (0: the best ranked), "distortions": (h,)
    ``map_distortion`` of every hypothesis after the last step it got (after the first round of the first step,
    for one dropped there), "dropped": (h,) bool, dropped before the last step, "confidence": float in [0, 1], no ground truth needed (several hypotheses: ``BestMap.confidence``,
    the kept map's distortion margin over the runner-up; given points: ``points_agreement``, the fraction of them
    the kept map kept before the refinement held them -- the starting map made from them, or the alternative as
    given: points that no near-isometric map keeps all of, e.g. left and right swapped, score low; absent with a
    single automatic hypothesis)} or ``skips.skipped(why)``. With given points and an
    ``alternative`` (another ``corr.dense_refine`` result of the same pair, e.g. dense_auto's) that keeps the given
    points, both maps get the registration once more with the points held and the less distorted is kept
    (``refine.with_alternative``; "hypothesis": "alternative" when it is that one): points do not make a map
    worse. ``second_opinion`` (automatic mode): the kept map, or the map made from the template's feature points
    and their images under it, held through the refinement, whichever is less distorted
    (``refine.second_opinion``; "hypothesis" and "confidence" stay those of the choice among the initial maps;
    docs/dense.md "A second opinion from the automatic map's own points"); asked with given points it is a
    ValueError (it would do nothing)."""
    if is_skipped(initial):
        return skipped(skip_reason(initial))
    if second_opinion and "points" in initial:              # checked before any work: the item fails at once
        raise ValueError("corr.dense_refine: second_opinion is for the automatic mode, and this initial map was made "
                         "from given points (corr.dense_init mode 'sparse'); set second_opinion only on the stage "
                         "that refines the automatic map (e.g. --set dense_auto.second_opinion=true)")
    if second_opinion and ("k_init" not in initial or "k_end" not in initial):
        raise ValueError("corr.dense_refine: second_opinion needs the initial map's k_init and k_end, which "
                         "corr.dense_init records; give 'initial' those keys (or second_opinion: false)")
    S, T = _basis(template_basis, "template"), _basis(target_basis, "target")
    starts = [(initial["C"], initial["p2p_samples"])]
    if "C_more" in initial:
        starts += list(zip(np.asarray(initial["C_more"]), np.asarray(initial["p2p_samples_more"])))
    maps = [dense.upsample_spectral(S, T, np.asarray(C), np.asarray(p2p)) for C, p2p in starts]
    plan = _refine_plan(refine=refine, n_patches=n_patches, patch_size=patch_size, rounds=rounds,
                        icp_iterations=icp_iterations, stiffness=stiffness)
    points = np.asarray(initial["points"]) if "points" in initial else None
    best = dense.refine_best(S, T, maps, plan, points=None if points is None else tuple(points))
    hypothesis = best.index
    if points is not None:
        unheld = maps[0]                # the kept map before the refinement held the points (it always keeps them)
        if holds(alternative, "vertex_map"):
            best = dense.with_alternative(S, T, best, alternative["vertex_map"], tuple(points), refine=plan)
            hypothesis = "alternative" if best.index == 1 else hypothesis
            if best.index == 1:
                unheld = map_to_local(S, T, alternative["vertex_map"])
        confidence = dense.points_agreement(T, unheld, tuple(points))
    else:
        confidence = best.confidence if len(maps) > 1 else None
        if second_opinion:
            best = dense.refine_second_opinion(S, T, best, plan, k_init=int(initial["k_init"]),
                                               k_end=int(initial["k_end"]))
    out = {"vertex_map": map_to_original(S, T, best.p2p), "hypothesis": hypothesis,
           "distortions": np.asarray(best.distortions),
           "dropped": np.asarray(best.dropped or (False,) * len(best.distortions))}
    return out if confidence is None else {**out, "confidence": float(confidence)}


def _given_maps(inputs: dict) -> dict:
    """{method: {mesh: (n_template,) int}} of the dense results that have a map."""
    return {method: {m: np.asarray(r["vertex_map"], np.int64) for m, r in sorted(res.items())
                     if holds(r, "vertex_map")} for method, res in inputs.items() if res}


@register("corr.place_landmarks", group="correspondence", fanout="once", writes_files=True)
def place_landmarks(template_mesh, landmarks, dense_sparse=None, dense_auto=None, *, out_dir: str) -> dict:
    """The template's landmarks placed on every test mesh through each dense map (``transfer_landmarks``).
    Files: ``<method>/<mesh>.txt`` (``vid,Name`` lines, 0-based target vertex ids, the template's names).

    Returns {"placed": {method: {mesh: (L,) int}}, "names": [L names], "files": [relative paths]}.
    """
    ids, names = read_landmarks(landmarks, n_vertices=len(template_mesh["V"]))
    placed, files = {}, []
    for method, maps in _given_maps({"dense_sparse": dense_sparse, "dense_auto": dense_auto}).items():
        placed[method] = {m: dense.transfer_landmarks(vm, ids) for m, vm in maps.items()}
        for m, target_ids in placed[method].items():
            files.append(f"{method}/{m}.txt")
            write_landmarks(os.path.join(out_dir, files[-1]), target_ids, names)
    return {"placed": placed, "names": list(names), "files": files}


DENSE_MAP_METHODS = ("mobius",) + METHODS


@register("corr.export_dense_maps", group="correspondence", fanout="once", writes_files=True)
def export_dense_maps(template_mesh, meshes, mobius=None, dense_sparse=None, dense_auto=None, *, colors: bool = True,
                      out_dir: str) -> dict:
    """Every dense map as a file, for use outside the project. Per method and target mesh:
    ``<method>/<mesh>.txt`` -- ``#`` header lines naming the template, the target and the method, then one line
    per template vertex i: its target vertex id (0-based, in the target file's vertex order; -1 off the
    template's kept component); ``corr_core.correspondence.dense.read_dense_map`` (or ``numpy.loadtxt``) reads
    it. With ``colors``, also ``<method>/<mesh>.ply``: the target mesh (its kept faces) with the template's
    coordinates as RGB pulled back through the map as vertex colours (same colour = corresponding point;
    opens in MeshLab or Blender), and ``template.ply``: the template coloured by its coordinates.

    meshes: {name: corr.mesh result}; method inputs: {test mesh: result with "vertex_map"} (skipped meshes,
    without a map, are left out). Returns {"files": [relative paths], "maps": {method: [meshes]}}.
    """
    Vs, Fs = np.asarray(template_mesh["V"]), np.asarray(template_mesh["F"])
    template = os.path.splitext(template_mesh.get("name") or "template")[0]
    files, written = [], {}
    palette = None
    if colors:
        kept = np.unique(Fs)
        palette = np.zeros_like(Vs, dtype=np.float64)
        palette[kept] = plotting.meshes.coordinate_colors(Vs[kept])
        save_ply(os.path.join(out_dir, "template.ply"), Vs, Fs, palette,
                 comments=[f"template {template}: its coordinates as RGB (compare the <method>/<mesh>.ply files)"])
        files.append("template.ply")
    inputs = {"mobius": mobius, "dense_sparse": dense_sparse, "dense_auto": dense_auto}
    for method, maps in _given_maps(inputs).items():
        os.makedirs(os.path.join(out_dir, method), exist_ok=True)
        for m, vm in maps.items():
            target = meshes[m]
            header = [f"dense map: template {template} ({len(Vs)} vertices) -> target {m} "
                      f"({target.get('name', m)}, {len(target['V'])} vertices), method {method}",
                      "line i (after these comments): target vertex id (0-based) of template vertex i; "
                      "-1: no image (off the template's kept component)"]
            with open(os.path.join(out_dir, method, f"{m}.txt"), "w", encoding="utf-8") as fh:
                fh.write(dense.format_dense_map(vm, header))
            files.append(f"{method}/{m}.txt")
            if colors:
                Vt = np.asarray(target["V"])
                save_ply(os.path.join(out_dir, method, f"{m}.ply"), Vt, np.asarray(target["F"]),
                         plotting.meshes.pull_back_colors(palette, vm, Vt),
                         comments=[f"target {m} coloured by template {template}'s coordinates through {method}"])
                files.append(f"{method}/{m}.ply")
            written.setdefault(method, []).append(m)
    return {"files": files, "maps": written}


def _true_map(template_mesh: dict, target_mesh: dict, ground_truth, name: str) -> tuple[np.ndarray | None, str]:
    """(n_template,) int true target vertex of each template vertex and where it comes from, or (None, why)."""
    n_s, n_t = len(template_mesh["V"]), len(target_mesh["V"])
    problem = numbered_like_template(target_mesh, template_mesh)
    if problem is None:     # the same triangles: vertex i <-> vertex i (-1 past the target's last vertex)
        return np.where(np.arange(n_s) < n_t, np.arange(n_s), -1), "identity"
    path = os.path.join(ground_truth, f"{name}.txt") if ground_truth else ""
    if not os.path.isfile(path):
        return None, (f"{name}: {problem}, and no ground_truth/{name}.txt: no dense ground truth, errors not "
                      "measured")
    truth = np.loadtxt(path, dtype=np.int64, ndmin=1)
    if truth.shape != (n_s,) or truth.min() < 0 or truth.max() >= n_t:
        raise ValueError(f"{path}: must hold {n_s} target vertex ids (one per template vertex, a line each) in "
                         f"0..{n_t - 1}; got {truth.size} ids in {truth.min()}..{truth.max()}")
    return truth, "file"


def _true_landmarks(template_mesh, target_mesh, landmarks, landmark_files, truth) -> np.ndarray | None:
    """(L,) int the target's true landmark vertices (own file, shared file, or the truth map), or None."""
    ids, _ = mesh_landmarks(target_mesh, landmarks, landmark_files, template_mesh)
    if ids is None and truth is not None:
        ids = truth[read_landmarks(landmarks, n_vertices=len(template_mesh["V"]))[0]]
    return ids


@register("corr.dense_measures", group="correspondence", fanout="item")
def dense_measures(template_mesh, target_mesh, landmarks, landmark_files=None, ground_truth=None, mobius=None,
                   dense_sparse=None, dense_auto=None, *, n_points: int = 2000, item_name: str = "") -> dict:
    """Errors of every dense map of one test mesh (geodesic on the target / sqrt(its area), heat method) at
    ``n_points`` farthest-point template vertices (all when fewer), and of the placed landmarks.

    Returns {"errors": {method: (p,)}, "truth": "identity" | "file", "landmark_errors": {method: (L,)},
    "nearest": {method: (L,) index of the true landmark nearest to each placed one}}; without a true map
    {"no_truth": why} and the landmark measures when the target's landmarks are known.
    """
    name = item_name or os.path.splitext(target_mesh["name"])[0]
    maps = {k: np.asarray(r["vertex_map"], np.int64) for k, r in
            (("mobius", mobius), ("dense_sparse", dense_sparse), ("dense_auto", dense_auto)) if holds(r, "vertex_map")}
    truth, source = _true_map(template_mesh, target_mesh, ground_truth, name)
    out = {"truth": source} if truth is not None else {"no_truth": source}
    Vt, Ft = np.asarray(target_mesh["V"]), np.asarray(target_mesh["F"])
    solver = None       # the target's geodesic solver, factorized once for every measure below
    if truth is not None:
        sub = IntrinsicMesh(template_mesh["V"], template_mesh["F"])
        vertices = sub.vids[farthest_point_samples(sub.V, min(n_points, len(sub.V)))]
        solver = GeodesicSolver(Vt, Ft)
        out["errors"] = dense_measures_lib.dense_errors(Vt, Ft, maps, truth, vertices=vertices, solver=solver)
    true_lms = _true_landmarks(template_mesh, target_mesh, landmarks, landmark_files, truth)
    if true_lms is not None:
        ids, _ = read_landmarks(landmarks, n_vertices=len(template_mesh["V"]))
        placed = {k: dense.transfer_landmarks(vm, ids) for k, vm in maps.items() if k in METHODS}
        if placed and solver is None:
            solver = GeodesicSolver(Vt, Ft)
        pairs = {k: dense_measures_lib.landmark_errors(Vt, Ft, p, true_lms, solver=solver) for k, p in placed.items()}
        out["landmark_errors"] = {k: e for k, (e, _) in pairs.items()}
        out["nearest"] = {k: n for k, (_, n) in pairs.items()}
    return out


def _per_mesh_rows(method: str, results: dict | None, per_mesh: dict) -> dict:
    """{mesh: {"mean_error": float | None (no ground truth), "landmark_accuracy": float | None,
    "confidence": float | None}} of one method's maps (skipped meshes left out)."""
    rows = {}
    for m, r in sorted((results or {}).items()):
        if is_skipped(r):
            continue
        measured = per_mesh.get(m, {})
        errors = measured.get("errors", {}).get(method)
        nearest = measured.get("nearest", {}).get(method)
        rows[m] = {"mean_error": float(np.mean(errors)) if errors is not None and len(errors) else None,
                   "landmark_accuracy": (dense_measures_lib.landmark_accuracy(nearest) if nearest is not None
                                     else None),
                   "confidence": float(r["confidence"]) if "confidence" in r else None}
    return rows


def _low_confidence_warnings(dense_summary: dict) -> list[str]:
    """One sentence per map whose confidence is below ``LOW_CONFIDENCE`` (``dense.refine``)."""
    out = []
    for method, summary in dense_summary.items():
        for m, row in summary.get("per_mesh", {}).items():
            c = row["confidence"]
            if c is not None and c < LOW_CONFIDENCE:
                why = ("few of the given points agree with the map made from them" if method == "dense_sparse" else
                       "another starting map (e.g. the shape turned by 180 degrees or mirrored) refined almost as well")
                out.append(f"{method} map of {m} has low confidence {c:.2f} ({why}): look at "
                           f"dense_maps/{method}/{m}.ply before using it")
    return out


def dense_reports(names: list[str], dense_sparse, dense_auto, per_mesh, out_dir: str) -> tuple[dict, dict]:
    """The dense part of ``corr.evaluate``: (method reports for the landmark accuracy, like the course
    methods', {mesh: {"all": nearest}}), and the summary {"dense": {method: summary}, "landmark_error":
    {method: mean}, "dense_n_points", "dense_skipped", "dense_not_measured"}; writes ``kim_curves.png``."""
    per_mesh = dict(sorted((per_mesh or {}).items()))
    preds = {method: {m: np.asarray(r["nearest"][method]) for m, r in per_mesh.items()
                      if method in r.get("nearest", {})} for method in METHODS}
    out: dict = {"dense_skipped": {k: v for k, v in (("dense_sparse", skip_reasons(dense_sparse)),
                                                     ("dense_auto", skip_reasons(dense_auto))) if v},
                 "dense_not_measured": {m: r["no_truth"] for m, r in per_mesh.items() if "no_truth" in r}}
    errors = {method: np.concatenate([r["errors"][method] for r in per_mesh.values()
                                      if method in r.get("errors", {})] or [np.zeros(0)])
              for method in ("mobius",) + METHODS}
    errors = {k: v for k, v in errors.items() if v.size}
    out["dense"] = {k: dense_measures_lib.summary(e) for k, e in errors.items() if k in METHODS}
    for method, results in (("dense_sparse", dense_sparse), ("dense_auto", dense_auto)):
        rows = _per_mesh_rows(method, results, per_mesh)
        if rows:
            out["dense"].setdefault(method, {})["per_mesh"] = rows
    out["warnings"] = _low_confidence_warnings(out["dense"])
    out["dense_n_points"] = {k: int(e.size) for k, e in errors.items()}
    lm = {method: [r["landmark_errors"][method] for r in per_mesh.values() if method in r.get("landmark_errors", {})]
          for method in METHODS}
    out["landmark_error"] = {k: float(np.mean(np.concatenate(v))) for k, v in lm.items() if v}
    if errors:
        t = dense_measures_lib.KIM_THRESHOLDS
        plotting.plot_error_curves({KIM_LABELS[k]: (t, dense_measures_lib.kim_curve(e)) for k, e in errors.items()},
                                   os.path.join(out_dir, "kim_curves.png"))
    reports = {method: measures.method_report(p, names) for method, p in preds.items() if p}
    return reports, {k: v for k, v in out.items() if v}
