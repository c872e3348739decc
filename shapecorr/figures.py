"""Figure stages: correspondences drawn on the meshes (landmark methods and dense maps) and, for alignment,
recovered against true azimuth. Each loads its inputs, calls ``corr_core`` and writes PNGs to ``out_dir``.

Dense maps plug in by name: ``corr.dense_figures`` takes one optional input per dense method, each
{test mesh: (n_template,) int target vertex per template vertex} (or {test mesh: {"vertex_map": ...}}).
"""
from __future__ import annotations

import csv
import os

import numpy as np

from corr_core import plotting_meshes
from corr_core.alignment.azimuth import agreement_up_to_offset
from corr_core.correspondence import matchers, mobius
from corr_core.correspondence.landmarks import read_landmarks, subset_positions
from corr_core.geometry.midedge import vertex_to_edge
from corr_core.geometry.primitives import surface_area

from stages.registry import register

MAX_POSES = 4          # poses per picture: the best, the worst, and evenly spaced ones between
VIEWS = (0, 1)         # front and three-quarter cameras of 8 around the y axis
WORST_FILE = "landmarks_worst_per_method.png"


def _spread(names_by_score: list[str], k: int = MAX_POSES) -> list[str]:
    """Up to ``k`` names from a best-to-worst list: always the first (best) and the last (worst)."""
    if len(names_by_score) <= k:
        return list(names_by_score)
    idx = np.unique(np.round(np.linspace(0, len(names_by_score) - 1, k)).astype(int))
    return [names_by_score[i] for i in idx]


def _mesh_pair(mesh: dict) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(mesh["V"]), np.asarray(mesh["F"])


def _template_name(template_mesh: dict, meshes: dict) -> str:
    """The item name of the template among ``meshes`` (the one with the very same vertices)."""
    for name, m in sorted(meshes.items()):
        if np.array_equal(np.asarray(m["V"]), np.asarray(template_mesh["V"])):
            return name
    return ""


def _landmark_methods(inputs: dict) -> dict:
    """{method: {test mesh: (L,) predictions}} of the given method inputs, test meshes with a truth only."""
    out = {}
    for method, results in inputs.items():
        preds = {m: np.asarray(r["all"]) for m, r in sorted((results or {}).items()) if "no_truth" not in r}
        if preds:
            out[method] = preds
    return out


@register("corr.landmark_figures", group="correspondence", fanout="once", writes_files=True)
def landmark_figures(template_mesh, meshes, landmarks, descriptor=None, mrf=None, mrf_oriented=None,
                     mobius_votes=None, *, out_dir: str) -> dict:
    """Per landmark method: the template and up to 4 test poses (best .. worst by accuracy) side by side, from
    two cameras, with the predicted landmarks as numbered dots (green right, red x wrong; the truth is
    landmark i -> landmark i). Files: ``landmarks_<method>.png``, and ``landmarks_worst_per_method.png`` (the
    template and each method's worst pose, front camera).

    meshes: {name: corr.mesh result}; method inputs: {test mesh: {"all": (L,) predicted landmark index}}.
    Returns {"figures": [file names], "poses": {method: [pose names shown, best first]}}.
    """
    ids, names = read_landmarks(landmarks, n_vertices=len(template_mesh["V"]))
    ids = np.asarray(ids, np.int64)
    methods = _landmark_methods({"descriptor": descriptor, "mrf": mrf, "mrf_oriented": mrf_oriented,
                                 "mobius": mobius_votes})
    figures, shown = [], {}
    for method, preds in methods.items():
        accuracy = {m: float(np.mean(p == np.arange(len(p)))) for m, p in preds.items()}
        poses = _spread(sorted(preds, key=lambda m: (-accuracy[m], m)))
        file = f"landmarks_{method}.png"
        mean = float(np.mean(list(accuracy.values())))
        plotting_meshes.plot_landmark_panels(
            _mesh_pair(template_mesh), {m: _mesh_pair(meshes[m]) for m in poses},
            {"template": ids, **{m: ids for m in poses}}, {m: preds[m] for m in poses}, list(names),
            f"{method}: landmarks on the best .. worst test poses (mean accuracy {mean:.2f})",
            os.path.join(out_dir, file), views=VIEWS)
        figures.append(file)
        shown[method] = poses
    if shown:   # one picture for the summary: every method's worst pose, front camera
        worst = {f"{method}: {poses[-1]}": (method, poses[-1]) for method, poses in shown.items()}
        plotting_meshes.plot_landmark_panels(
            _mesh_pair(template_mesh), {k: _mesh_pair(meshes[pose]) for k, (_, pose) in worst.items()},
            {"template": ids, **{k: ids for k in worst}}, {k: methods[m][pose] for k, (m, pose) in worst.items()},
            list(names), "the worst test pose of each method", os.path.join(out_dir, WORST_FILE), views=VIEWS[:1],
            wrap=3, legend=False)
        figures.insert(0, WORST_FILE)
    return {"figures": figures, "poses": shown}


def mobius_vertex_map(template_flat: dict, target_flat: dict, template_mesh: dict, target_mesh: dict,
                      sparse: np.ndarray, K: float = 0.5, metric: str = "surface", K_scale: float = 0.3,
                      power: float = 4.0) -> np.ndarray:
    """The dense map of Möbius voting's best map (as ``corr.match_mobius`` computes it) for every template
    vertex: (n_template,) int target vertex ids (via each vertex's first edge midpoint)."""
    s = matchers.mobius_inputs(template_flat, template_mesh["area"], sparse, metric)
    t = matchers.mobius_inputs(target_flat, target_mesh["area"], sparse, metric)
    surface = metric == "surface"
    res = mobius.mobius_vote_landmarks(s["samples"], t["samples"], s["sparse"], t["sparse"], K=K, metric=metric,
                                       lam_samples=(s["lam_samples"], t["lam_samples"]) if surface else None,
                                       lam_landmarks=(s["lam_sparse"], t["lam_sparse"]) if surface else None,
                                       power=power, K_scale=K_scale if surface else None)
    best = (res["consensus_maps"] or res["best_maps"])[0]
    src_eids = vertex_to_edge(np.arange(len(template_mesh["V"])), template_flat["edges"])
    nn = mobius.dense_map(best, s["Z"][src_eids], t["Z"], metric="plane" if surface else metric)
    return np.asarray(target_flat["edges"][nn, 0], np.int64)


@register("corr.mobius_dense_map", group="correspondence", fanout="item")
def mobius_dense_map(template, target, template_mesh, target_mesh, landmarks, sparse_landmarks, *,
                     K: float = 0.5, metric: str = "surface", K_scale: float = 0.3, power: float = 4.0) -> dict:
    """The full dense map of Möbius voting (the same vote as ``corr.match_mobius``; give it the same params):
    {"vertex_map": (n_template,) int target vertex of each template vertex}."""
    ids, _ = read_landmarks(landmarks, n_vertices=len(template_mesh["V"]))
    sids, _ = read_landmarks(sparse_landmarks, n_vertices=len(template_mesh["V"]))
    sparse = subset_positions(np.asarray(ids), np.asarray(sids), subset_name=sparse_landmarks, full_name=landmarks)
    return {"vertex_map": mobius_vertex_map(template, target, template_mesh, target_mesh, sparse, K=K,
                                            metric=metric, K_scale=K_scale, power=power)}


def _vertex_maps(results) -> dict:
    """{test mesh: (n_template,) int} from {test mesh: array or {"vertex_map": array}}."""
    out = {}
    for m, r in sorted((results or {}).items()):
        out[m] = np.asarray(r["vertex_map"] if isinstance(r, dict) else r, np.int64)
    return out


def _euclidean_error(template_V: np.ndarray, target: dict, vertex_map: np.ndarray) -> float | None:
    """Mean distance / sqrt(area) between each template vertex's image and the same vertex id on the target
    (the truth "vertex i <-> vertex i"); None when the vertex counts differ (no such truth)."""
    V = np.asarray(target["V"])
    if len(V) != len(template_V):
        return None
    return float(np.linalg.norm(V[vertex_map] - V, axis=1).mean() / np.sqrt(surface_area(V, target["F"])))


@register("corr.dense_figures", group="correspondence", fanout="once", writes_files=True)
def dense_figures(template_mesh, meshes, mobius=None, dense_sparse=None, dense_auto=None, *,
                  out_dir: str) -> dict:
    """Per dense method: the template coloured by its coordinates (as RGB) and up to 4 test poses coloured by
    that function pulled back through the method's map (best .. worst by the mean Euclidean error against
    vertex i <-> vertex i, when that truth exists). Files: ``dense_<method>.png``.

    meshes: {name: corr.mesh result}; each method input: {test mesh: (n_template,) int or {"vertex_map": ...}}.
    Returns {"figures": [file names], "mean_error": {method: {pose: error / sqrt(area)}}}.
    """
    template = _mesh_pair(template_mesh)
    figures, errors = [], {}
    for method, results in {"mobius": mobius, "dense_sparse": dense_sparse, "dense_auto": dense_auto}.items():
        maps = _vertex_maps(results)
        if not maps:
            continue
        err = {m: _euclidean_error(template[0], meshes[m], vm) for m, vm in maps.items()}
        order = sorted(maps, key=lambda m: (err[m] is None, err[m] or 0.0, m))
        poses = _spread(order)
        captions = {m: f"mean error {err[m]:.3f}" for m in poses if err[m] is not None}
        file = f"dense_{method}.png"
        plotting_meshes.plot_dense_panels(
            template, {m: _mesh_pair(meshes[m]) for m in poses}, {m: maps[m] for m in poses}, captions,
            f"{method}: template coordinates as RGB, pulled back through the dense map (best .. worst pose)",
            os.path.join(out_dir, file), views=VIEWS)
        figures.append(file)
        errors[method] = {m: e for m, e in err.items() if e is not None}
    return {"figures": figures, "mean_error": errors}


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
    recovered = (rec - offset) % V
    plotting_meshes.plot_azimuths(true * 360.0 / V, recovered * 360.0 / V, names, 360.0 / V,
                                  os.path.join(out_dir, "azimuth_recovered_vs_true.png"))
    return {"figures": ["azimuth_recovered_vs_true.png"], "exact": float(exact)}
