"""Figure stages: correspondences drawn on the meshes (landmark methods and dense maps) and, for alignment,
recovered against true azimuth. Each loads its inputs, calls ``corr_core`` and writes PNGs to ``out_dir``.

Dense maps plug in by name: ``corr.dense_figures`` takes one optional input per dense method, each
{test mesh: (n_template,) int target vertex per template vertex} (or {test mesh: {"vertex_map": ...}}, e.g.
the results of ``corr.match_mobius``).
"""
from __future__ import annotations

import csv
import os

import numpy as np

from corr_core.alignment.azimuth import agreement_up_to_offset
from corr_core.correspondence.landmarks import read_landmarks
from corr_core.plotting import meshes as mesh_plots

from stages.registry import register

from .landmark_sources import mesh_landmarks
from .skips import without_skipped

VIEWS = (0, 1)         # front and three-quarter cameras of 8 around the y axis


def _mesh_pair(mesh: dict) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(mesh["V"]), np.asarray(mesh["F"])


def _landmark_methods(inputs: dict) -> dict:
    """{method: {test mesh: (L,) predictions}} of the given method inputs, test meshes with a truth only."""
    out = {}
    for method, results in inputs.items():
        preds = {m: np.asarray(r["all"]) for m, r in sorted(without_skipped(results).items())
                 if "no_truth" not in r and "all" in r}
        if preds:
            out[method] = preds
    return out


@register("corr.landmark_figures", group="correspondence", fanout="once", writes_files=True)
def landmark_figures(template_mesh, meshes, landmarks, descriptor=None, mrf=None, mrf_oriented=None,
                     mobius_votes=None, landmark_files=None, *, out_dir: str) -> dict:
    """Per landmark method: the template and up to 4 test poses (best .. worst by accuracy) side by side, from
    two cameras, with the predicted landmarks as numbered dots (green right, red x wrong; the truth is
    landmark i -> landmark i). Each pose's landmarks are drawn where its own landmarks are
    (``mesh_landmarks``: its file landmarks/<mesh>.txt, or the shared file on a mesh with the template's
    triangles); a pose with neither is left out. Files: ``landmarks_<method>.png``, and
    ``landmarks_worst_per_method.png`` (the template and each method's worst pose, front camera).

    meshes: {name: corr.mesh result}; method inputs: {test mesh: {"all": (L,) predicted landmark index}}.
    Returns {"figures": [file names], "poses": {method: [pose names shown, best first]}}.
    """
    ids, names = read_landmarks(landmarks, n_vertices=len(template_mesh["V"]))
    methods = _landmark_methods({"descriptor": descriptor, "mrf": mrf, "mrf_oriented": mrf_oriented,
                                 "mobius": mobius_votes})
    vids = {m: mesh_landmarks(meshes[m], landmarks, landmark_files, template_mesh)[0]
            for m in sorted({m for p in methods.values() for m in p})}
    methods = {k: {m: p for m, p in preds.items() if vids[m] is not None} for k, preds in methods.items()}
    methods = {k: preds for k, preds in methods.items() if preds}
    figures, shown = mesh_plots.plot_landmark_methods(
        _mesh_pair(template_mesh), {m: _mesh_pair(meshes[m]) for p in methods.values() for m in p},
        {"template": np.asarray(ids, np.int64), **{m: v for m, v in vids.items() if v is not None}},
        list(names), methods, out_dir, views=VIEWS)
    return {"figures": figures, "poses": shown}


def _vertex_maps(results) -> dict:
    """{test mesh: (n_template,) int} from {test mesh: array or {"vertex_map": array}} (results without a map,
    e.g. a skipped mesh, are left out)."""
    return {m: np.asarray(r["vertex_map"] if isinstance(r, dict) else r, np.int64)
            for m, r in sorted(without_skipped(results).items()) if not isinstance(r, dict) or "vertex_map" in r}


def _mean_errors(maps: dict, dense_measures) -> dict:
    """{method: {pose: mean error or None}}: the mean of ``corr.dense_measures``' errors of the pose (geodesic on
    the target / sqrt(its area), against the true map: the measure of the results' "dense" table); None
    without a true map."""
    per_pose = dense_measures or {}
    return {method: {m: (float(np.mean(per_pose[m]["errors"][method]))
                         if method in per_pose.get(m, {}).get("errors", {}) else None) for m in mm}
            for method, mm in maps.items()}


@register("corr.dense_figures", group="correspondence", fanout="once", writes_files=True)
def dense_figures(template_mesh, meshes, mobius=None, dense_sparse=None, dense_auto=None, dense_measures=None, *,
                  out_dir: str) -> dict:
    """Per dense method: the template coloured by its coordinates (as RGB) and up to 4 test poses coloured by
    that function pulled back through the method's map (best .. worst by the pose's mean error from
    ``dense_measures``: geodesic on the target / sqrt(area) against the true map, as in the results' "dense"
    table; poses without a true map come last, uncaptioned). Files: ``dense_<method>.png``.

    meshes: {name: corr.mesh result}; each method input: {test mesh: (n_template,) int or {"vertex_map": ...}};
    dense_measures: {test mesh: corr.dense_measures result}.
    Returns {"figures": [file names], "mean_error": {method: {pose: mean geodesic error}}}.
    """
    inputs = {"mobius": mobius, "dense_sparse": dense_sparse, "dense_auto": dense_auto}
    maps = {method: _vertex_maps(r) for method, r in inputs.items() if _vertex_maps(r)}
    errors = _mean_errors(maps, dense_measures)
    figures = mesh_plots.plot_dense_methods(_mesh_pair(template_mesh),
                                            {m: _mesh_pair(meshes[m]) for mm in maps.values() for m in mm},
                                            maps, errors, out_dir, views=VIEWS)
    return {"figures": figures,
            "mean_error": {method: {m: e for m, e in err.items() if e is not None} for method, err in errors.items()}}


def _read_truth(path) -> dict[str, int]:
    with open(path, newline="", encoding="utf-8") as fh:
        return {row["shape"]: int(row["azimuth_steps"]) for row in csv.DictReader(fh)}


@register("align.azimuth_figure", group="alignment", fanout="once", writes_files=True)
def azimuth_figure(solution, ground_truth=None, *, out_dir: str) -> dict:
    """Recovered against true azimuth for every shape with a known one (generated data), after removing the
    best global offset (alignment is only defined up to one): right shapes lie on the diagonal.
    File: ``azimuth_recovered_vs_true.png``; nothing when there is no ground truth.

    Returns {"figures": [file names], "exact": fraction on the diagonal}.
    """
    if not ground_truth:
        return {"figures": []}
    truth = _read_truth(ground_truth)
    names = [n for n in solution["names"] if n in truth]
    if not names:
        return {"figures": []}
    V = int(solution["n_views"])
    labels = dict(zip(solution["names"], np.asarray(solution["labels"], np.int64)))
    rec = np.array([labels[n] for n in names])
    true = np.array([truth[n] for n in names])
    exact, offset = agreement_up_to_offset(rec, true, V)
    mesh_plots.plot_azimuths(true * 360.0 / V, ((rec - offset) % V) * 360.0 / V, names, 360.0 / V,
                             os.path.join(out_dir, "azimuth_recovered_vs_true.png"))
    return {"figures": ["azimuth_recovered_vs_true.png"], "exact": float(exact)}
