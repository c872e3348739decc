"""Stage wiring for problem 2: landmark correspondence from a template mesh to each test pose.

Per mesh (cached per mesh): mesh check -> spectral descriptors (HKS, WKS) at the landmarks, landmark
geodesics (normalized by the geodesic diameter), mid-edge flattening with surface samples.
Per test mesh (one stage per method, so changing the MRF sigma or K reruns only that matching):
descriptors + Hungarian, geodesic-consistency MRF (Leordeanu & Hebert), Möbius voting.
Once: accuracies, frequency-matrix figures, dense-map error curves.
"""
from __future__ import annotations

import json
import os
import warnings as _warnings

import numpy as np

from corr_core import plotting
from corr_core.correspondence import matchers, measures, mesh_features
from corr_core.correspondence.landmarks import read_landmarks
from corr_core.geometry import checks as meshcheck
from corr_core.geometry.mesh_io import load_mesh
from corr_core.geometry.primitives import mesh_edges, surface_area, triangles_key
from corr_core.geometry.repair import repair_mesh, warn_repairs

from stages.registry import register
from stages.skipped import Skipped

from .dense import dense_reports
from .landmark_sources import mesh_landmarks, no_landmarks_result, sparse_positions
from .skips import skip_reasons, skipped, without_skipped


@register("corr.mesh", group="correspondence", fanout="item")
def mesh(path, *, item_name: str | None = None) -> dict:
    """Load, repair (vertex ids kept) and check one mesh for the intrinsic methods: welded along its seams (the
    faces re-pointed from a vertex's copies to the vertex, ``repair.coincident_representatives``), faces turned
    outward when they all point inward (``repair.orient_outward``), only the largest connected component kept (its faces; the
    vertices of small loose pieces and those no face uses stay in V, with their ids, and every method ignores
    them: ``corr_core.geometry.intrinsic.IntrinsicMesh``).

    Returns {"V": (n,3) float64 all vertices in file order, "F": (m,3) int64 repaired faces of the largest
    component, "area": float (of F), "name": file name, "item": item name, "warnings": [str], "repairs": [dict]
    (``corr_core.geometry.repair``: what was dropped / flipped / ignored, each naming the file)}. ``item_name`` puts
    the item in the cache key: two files with the same content get their own entries, each with its own name
    (by which the per-mesh files landmarks/<mesh>.txt and ground_truth/<mesh>.txt are found).
    """
    name = os.path.basename(path)
    V, F = load_mesh(path)
    F, repairs = repair_mesh(V, F, name, keep_largest_component=True, outward=True, weld=True)
    warn_repairs(repairs)
    warnings = meshcheck.check_correspondence_mesh(V, F, name=name, allow_unreferenced=True)
    return {"V": V, "F": F.astype(np.int64), "area": surface_area(V, F), "name": name, "item": item_name,
            "warnings": list(warnings), "repairs": [r.as_dict() for r in repairs]}


@register("corr.spectral", group="correspondence", fanout="item")
def spectral(mesh, landmarks, landmark_files=None, template_mesh=None, *, k: int = 100, n_times: int = 16,
             n_energies: int = 100, wks_variance: float = 6.0) -> dict:
    """HKS and WKS at the landmark vertices (``mesh_landmarks``) from the first k Laplace-Beltrami eigenpairs.

    Returns {"hks": (L, n_times), "wks": (L, n_energies), "evals": (k,), "n_vertices", "landmark_source"}, or
    {"no_landmarks": why} for a mesh without landmarks.
    """
    ids, source = mesh_landmarks(mesh, landmarks, landmark_files, template_mesh)
    if ids is None:
        return no_landmarks_result(mesh, source)
    out = mesh_features.spectral_features(mesh["V"], mesh["F"], ids, k=k, n_times=n_times, n_energies=n_energies,
                                          wks_variance=wks_variance)
    return {**out, **_numbering(mesh), "landmark_source": source}  # matchers: does the truth apply


@register("corr.geodesics", group="correspondence", fanout="item")
def geodesics(mesh, landmarks, landmark_files=None, template_mesh=None) -> dict:
    """Landmark geodesic distances normalized by the geodesic diameter, and landmark chirality.

    Returns {"D": (L,L) float, "diameter": float, "chirality": (L,L,L) float, ...} or {"no_landmarks": why}.
    """
    ids, source = mesh_landmarks(mesh, landmarks, landmark_files, template_mesh)
    if ids is None:
        return no_landmarks_result(mesh, source)
    return {**mesh_features.geodesic_features(mesh["V"], mesh["F"], ids), **_numbering(mesh),
            "landmark_source": source}


def _given_flat(folder, item_path: str, n_edges: int):
    """Z from a given flattened mesh (course layout: flattened_meshes/<template|test>/<name>.obj), if any."""
    if not folder:
        return None
    sub = os.path.basename(os.path.dirname(item_path))
    candidate = os.path.join(folder, sub, os.path.basename(item_path))
    if not os.path.isfile(candidate):
        return None
    P, _ = load_mesh(candidate, require_faces=False)
    if len(P) != n_edges:
        raise ValueError(f"{candidate}: has {len(P)} vertices but the mesh has {n_edges} edges; "
                         "a flattened mesh must have one vertex per edge")
    return P[:, 0] + 1j * P[:, 1]


@register("corr.flatten", group="correspondence", fanout="item")
def flatten(mesh, path, landmarks, flattened=None, samples=None, landmark_files=None, template_mesh=None, *,
            source: str = "compute", sample_source: str = "auto", n_samples: int = 300) -> dict:
    """Mid-edge flattening (one complex point per edge) and uniform surface samples.

    source: "compute" (the project's own flattening, the default: on SCAPE it is more accurate than the course
    files, which are stored with 6 digits), "given" / "auto" (use the mesh's file in ``flattened`` =
    flattened_meshes/{template,test}/ when present, else compute it).
    sample_source: "fps" (farthest-point samples of the edge midpoints), "given" / "auto" (the vertex ids in
    ``samples``, e.g. uniform_sample_vids.txt, when present, else fps). Note: the course's sample file lists the
    same vertex ids for every mesh, i.e. samples already in correspondence; "fps" does not use that.
    Returns {"Z": (E,2) float (x, y), "lam": (E,) local scale of the flattening, "landmark_eids": (L,),
    "sample_eids": (S,), "edges": (E,2), "area": float, "source": str, "sample_source": str}, or
    {"no_landmarks": why} (``mesh_landmarks``).
    """
    V, F = mesh["V"], mesh["F"]
    if source not in ("auto", "compute", "given"):
        raise ValueError(f"source must be 'auto', 'compute' or 'given', got {source!r}")
    if sample_source not in ("auto", "fps", "given"):
        raise ValueError(f"sample_source must be 'auto', 'fps' or 'given', got {sample_source!r}")
    given = _given_flat(flattened, path, len(mesh_edges(F)[0])) if source in ("auto", "given") else None
    sample_vids = None
    if sample_source in ("auto", "given") and samples:
        sample_vids, _ = read_landmarks(samples, n_vertices=len(V))
    ids, landmark_source = mesh_landmarks(mesh, landmarks, landmark_files, template_mesh)
    if ids is None:
        return no_landmarks_result(mesh, landmark_source)
    out = mesh_features.flattening_features(V, F, ids, Z=given, sample_vids=sample_vids, n_samples=n_samples)
    return {**out, "area": float(mesh["area"]), "source": "computed" if given is None else "given",
            "sample_source": "fps" if sample_vids is None else "given", "landmark_source": landmark_source}


def _numbering(mesh: dict) -> dict:
    """What a per-mesh result keeps of the mesh's vertex numbering, for the matchers (``_mark_truth``)."""
    return {"n_vertices": len(mesh["V"]), "n_faces": len(mesh["F"]), "triangles": triangles_key(mesh["F"])}


def _mark_truth(result: dict, template: dict, target: dict) -> dict:
    """Add "no_truth" (why) to a matcher's result when the landmark truth "landmark i <-> landmark i" does not
    apply to this test mesh: its landmarks come from the shared file but its triangles are not the template's
    (``measures.triangles_problem``). A mesh with its own landmark file, named like the template's, has it
    whatever its numbering."""
    if target.get("landmark_source") == "own":
        return result
    problem = measures.triangles_problem(template.get("triangles"), target.get("triangles"),
                                         template.get("n_faces"), target.get("n_faces"),
                                         template.get("n_vertices"), target.get("n_vertices"))
    return {**result, "no_truth": f"{problem}; not scored"} if problem else result


def _skipped_match(target: dict) -> Skipped | None:
    """A matcher's result for a test mesh without landmarks (``skips.skipped``: not matched, not scored), else
    None."""
    why = target.get("no_landmarks")
    return skipped(why) if why else None


@register("corr.match_descriptor", group="correspondence", fanout="item")
def match_descriptor(template, target, landmarks, sparse_landmarks, *, descriptor: str = "hks+wks",
                     metric: str = "relative_l1") -> dict:
    """(a) Descriptor distance + Hungarian assignment, with all landmarks and with the sparse ones.

    Returns {"all": (L,) predicted target landmark per template landmark, "sparse": (k,) within the sparse set}.
    """
    if (skip := _skipped_match(target)) is not None:
        return skip
    out = matchers.match_descriptors(template, target, sparse_positions(landmarks, sparse_landmarks),
                                     descriptor=descriptor, metric=metric)
    return _mark_truth(out, template, target)


@register("corr.match_mrf", group="correspondence", fanout="item")
def match_mrf(template, target, landmarks, sparse_landmarks, *, sigma: float = 0.05,
              orientation: bool = False) -> dict:
    """(b) Pairwise geodesic-consistency MRF, w = exp(-(d(ia,ja) - d(ib,jb))^2 / (2 sigma)), solved by
    Leordeanu & Hebert; ``orientation`` adds the chirality test that resolves left/right swaps.

    Returns {"all": (L,), "sparse": (k,)}.
    """
    if (skip := _skipped_match(target)) is not None:
        return skip
    out = matchers.match_geodesic_mrf(template, target, sparse_positions(landmarks, sparse_landmarks), sigma=sigma,
                                      orientation_test=orientation)
    return _mark_truth(out, template, target)


@register("corr.match_mobius", group="correspondence", fanout="item")
def match_mobius(template, target, template_mesh, target_mesh, landmarks, sparse_landmarks, *, K: float = 0.5,
                 metric: str = "surface", K_scale: float = 0.7, power: float = 4.0, top: int = 100,
                 dense_points: int = 200) -> dict:
    """(c) Möbius voting on the flattened meshes from triplets of sparse landmarks, extended to all landmarks
    by the consensus maps; plus a dense map from the best map and its geodesic errors.

    K: deformation-error threshold; with metric "surface" in units of the sample spacing
    sqrt(area / n_samples) (docs/mobius_notes.md), with "plane" in canonical-frame units (the paper).
    K 0.5, power 4, K_scale 0.7 (every pipeline): fitted on generated humanoids of seeds no pipeline uses by
    ``python bench/mobius_sweep.py --seeds 10-12 --poses 6 [--other-bodies]`` (K_scale 0.7 matched 0.04-0.07 more
    of the sparse landmarks than 0.3; 0.5-1.0 a plateau; docs/mobius_notes.md, "In the pipeline").
    Returns {"sparse": (k,), "all": (L,), "dense_errors": (dense_points,) geodesic error / sqrt(area),
    "best_score": float, "vertex_map": (n_template,) int target vertex of each template vertex}. The dense
    errors need the truth "vertex i <-> vertex i", i.e. the same vertex count and faces as the template;
    otherwise they are left out and "dense_skipped" (str) says why. A test mesh without landmarks:
    ``skips.skipped(why)``.
    """
    if (skip := _skipped_match(target)) is not None:
        return skip
    out = matchers.match_mobius(template, target, template_mesh, target_mesh,
                                sparse_positions(landmarks, sparse_landmarks), K=K, metric=metric, K_scale=K_scale,
                                power=power, top=top, dense_points=dense_points)
    return _mark_truth(out, _numbering(template_mesh), {**_numbering(target_mesh), **target})


# (label, method input, prediction key) of each reported method, in report order
_REPORTS = (("descriptor", "descriptor", "all"), ("descriptor_sparse", "descriptor", "sparse"),
            ("mrf", "mrf", "all"), ("mrf_sparse", "mrf", "sparse"), ("mrf_oriented", "mrf_oriented", "all"),
            ("mrf_oriented_sparse", "mrf_oriented", "sparse"), ("mobius_sparse", "mobius_votes", "sparse"),
            ("mobius_all", "mobius_votes", "all"))


def _frequency_figure(label: str, report: dict, rows: list[str], out_dir: str) -> tuple:
    """``plotting.plot_frequency_matrices``'s entry for one method's accumulated frequency matrix."""
    title = (f"{label}: accumulated correspondences ({len(report['per_mesh'])} meshes, "
             f"accuracy {report['accuracy']:.3f})")
    return report["frequency"], rows, rows, title, os.path.join(out_dir, f"frequency_{label}.png")


def _dense_report(mobius_votes: dict, out_dir: str) -> dict:
    """Geodesic error curve of the Möbius dense maps (Kim et al. 2011 measure) and the meshes skipped."""
    out = {}
    made = without_skipped(mobius_votes)
    not_made = {**skip_reasons(mobius_votes),
                **{m: r["dense_skipped"] for m, r in made.items() if "dense_skipped" in r}}
    if not_made:
        out["dense_map_skipped"] = dict(sorted(not_made.items()))
    errors = np.concatenate([np.asarray(r["dense_errors"]) for r in made.values() if "dense_errors" in r]
                            or [np.zeros(0)])
    if errors.size:
        thresholds = measures.DENSE_ERROR_THRESHOLDS
        curve = measures.geodesic_error_curve(errors, thresholds)
        plotting.plot_error_curves({"Möbius dense map": (thresholds, curve)},
                                   os.path.join(out_dir, "dense_map_error_curve.png"))
        out["dense_map"] = measures.dense_map_summary(errors)
    return out


def _drop_unscorable(inputs: dict) -> tuple[dict, dict[str, str]]:
    """The method inputs {method: {mesh: result}} without the meshes that have no ground truth, and
    {mesh: why}; each such mesh is warned about."""
    not_scored: dict[str, str] = {}
    for method, results in inputs.items():
        if results:
            not_scored.update(skip_reasons(results))
            inputs[method], no_truth = measures.scorable_results(without_skipped(results))
            not_scored.update(no_truth)
    for mesh_name, reason in sorted(not_scored.items()):
        _warnings.warn(f"{mesh_name}: {reason}", UserWarning, stacklevel=3)
    return inputs, not_scored


def _method_reports(inputs: dict, names: list[str], sparse_names: list[str]) -> dict:
    """{label: ``measures.method_report``} of each course method with scorable results (``_REPORTS`` order)."""
    reports = {}
    for label, method, key in _REPORTS:
        if inputs[method]:
            preds = {mesh_name: np.asarray(r[key]) for mesh_name, r in sorted(inputs[method].items())}
            reports[label] = measures.method_report(preds, sparse_names if key == "sparse" else names)
    return reports


@register("corr.evaluate", group="correspondence", fanout="once", writes_files=True)
def evaluate(landmarks, sparse_landmarks, descriptor=None, mrf=None, mrf_oriented=None, mobius_votes=None,
             dense_sparse=None, dense_auto=None, dense_measures=None, *, frequency_figures: bool = True,
             out_dir: str) -> dict:
    """Accuracy per method (correct / all over test meshes x landmarks), per-mesh binary correspondence
    matrices (correspondences.json), accumulated frequency matrices as figures with landmark names
    (``frequency_<method>.png``, about 0.5 s each; ``frequency_figures: false`` skips them, e.g. in sweeps and
    tests), and the dense-map geodesic error curve.

    Each course method input is {test mesh: {"all": (L,), "sparse": (k,)}}; the truth is landmark i ->
    landmark i (the template's and the test's landmark files list the same anatomical points in the same order).
    The dense methods (``shapecorr.dense``): dense_sparse / dense_auto {test mesh: corr.dense_refine result},
    dense_measures {test mesh: corr.dense_measures result}; their landmark accuracy counts a placed landmark as
    right when its nearest true landmark has its name ("dense", "landmark_error": ``dense_reports``).
    """
    _, names = read_landmarks(landmarks)
    sparse_names = [names[i] for i in sparse_positions(landmarks, sparse_landmarks)]
    inputs = {"descriptor": descriptor, "mrf": mrf, "mrf_oriented": mrf_oriented, "mobius_votes": mobius_votes}
    inputs, not_scored = _drop_unscorable(inputs)
    reports = _method_reports(inputs, names, sparse_names)
    dense_method_reports, dense_out = dense_reports(names, dense_sparse, dense_auto, dense_measures, out_dir)
    reports.update(dense_method_reports)
    sparse_rows = {label for label, _, key in _REPORTS if key == "sparse"}
    if frequency_figures:
        plotting.plot_frequency_matrices([_frequency_figure(label, report, sparse_names if label in sparse_rows
                                                            else names, out_dir) for label, report in reports.items()])
    with open(os.path.join(out_dir, "correspondences.json"), "w", encoding="utf-8") as fh:
        json.dump({"landmarks": names, "sparse_landmarks": sparse_names,
                   "matrices": {k: r["matrices"] for k, r in reports.items()}}, fh)
    accuracy = {k: r["accuracy"] for k, r in reports.items()}
    plotting.plot_accuracy_bars(accuracy, os.path.join(out_dir, "accuracy.png"))
    out = {"accuracy": accuracy, "accuracy_per_mesh": {k: r["per_mesh"] for k, r in reports.items()},
           "top_confusions": {k: r["confusions"] for k, r in reports.items()}, **dense_out}
    if not_scored:
        out["not_scored"] = not_scored  # {test mesh: why it has no ground truth}
    if mobius_votes:
        out.update(_dense_report(mobius_votes, out_dir))
    return out
