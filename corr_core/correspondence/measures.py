"""Evaluating correspondences: landmark accuracy, confusion/frequency matrices, per-method reports, geodesic
error curves and dense-map summaries (figures: ``corr_core.plotting``).

Dense-map measure of Kim, Lipman & Funkhouser 2011 (Blended Intrinsic Maps): for each evaluated point, the
geodesic distance on the target surface between the predicted and the true image, divided by sqrt(area of
the target surface); a curve reports the fraction of points whose error is <= each threshold in 0..0.25.
"""
from __future__ import annotations

import numpy as np

from corr_core.geometry.geodesic import GeodesicSolver
from corr_core.geometry.primitives import same_triangles, surface_area


def correspondence_matrix(pred: np.ndarray, n_labels: int) -> np.ndarray:
    """Binary assignment matrix.

    Args: pred: (n,) int label of each node, in 0..n_labels-1. Returns: (n, n_labels) uint8, one 1 per row.
    """
    pred = np.asarray(pred, dtype=np.int64)
    if len(pred) and (pred.min() < 0 or pred.max() >= n_labels):
        raise ValueError(f"labels must be in 0..{n_labels - 1}")
    C = np.zeros((len(pred), n_labels), dtype=np.uint8)
    C[np.arange(len(pred)), pred] = 1
    return C


def accuracy(pred: np.ndarray, truth: np.ndarray) -> float:
    """Fraction of nodes whose predicted label equals the true one. pred, truth: (n,) int."""
    pred, truth = np.asarray(pred), np.asarray(truth)
    if pred.shape != truth.shape:
        raise ValueError(f"shape mismatch {pred.shape} vs {truth.shape}")
    return float(np.mean(pred == truth)) if pred.size else float("nan")


def frequency_matrix(matrices) -> np.ndarray:
    """Average of binary correspondence matrices: entry (i, a) = fraction of shapes mapping node i to label a.

    Args: matrices: sequence of (n,L) binary arrays. Returns: (n,L) float in [0,1]; rows sum to 1.
    """
    stack = np.asarray([np.asarray(m, dtype=np.float64) for m in matrices])
    if stack.ndim != 3 or len(stack) == 0:
        raise ValueError("need a non-empty list of (n,L) matrices")
    return stack.mean(axis=0)


def geodesic_error_curve(errors_normalized: np.ndarray, thresholds: np.ndarray | None = None) -> np.ndarray:
    """Cumulative error curve: fraction of errors <= each threshold.

    Args: errors_normalized: (p,) float, geodesic error / sqrt(area); thresholds: (T,) default linspace(0,.25,51).
    Returns: (T,) float in [0,1], non-decreasing.
    """
    thresholds = np.linspace(0.0, 0.25, 51) if thresholds is None else np.asarray(thresholds, dtype=np.float64)
    err = np.sort(np.asarray(errors_normalized, dtype=np.float64).ravel())
    if err.size == 0:
        raise ValueError("no errors given")
    return np.searchsorted(err, thresholds, side="right") / err.size


def geodesic_errors(V: np.ndarray, F: np.ndarray, pred_vids, true_vids) -> np.ndarray:
    """Kim–Lipman–Funkhouser error of predicted vertex images on the target mesh (V, F).

    Args: pred_vids, true_vids: (p,) int vertex ids on the target. Returns: (p,) float, geodesic distance
    (heat method) between predicted and true vertex divided by sqrt(surface area); dimensionless.
    """
    pred_vids = np.asarray(pred_vids, dtype=np.int64)
    true_vids = np.asarray(true_vids, dtype=np.int64)
    solver = GeodesicSolver(V, F)
    err = np.zeros(len(pred_vids))
    wrong = pred_vids != true_vids
    for t in np.unique(true_vids[wrong]):  # one heat solve per distinct true vertex
        rows = np.flatnonzero(wrong & (true_vids == t))
        err[rows] = solver.distance(int(t))[pred_vids[rows]]
    return err / np.sqrt(surface_area(V, F))


def top_confusions(matrices: list[np.ndarray], rows: list[str], *, k: int = 10) -> dict[str, int]:
    """The k most frequent wrong correspondences 'A -> B' (rows[i] -> rows[j], i != j) over binary (n,n)
    correspondence matrices, with how many matrices (meshes) made them; most frequent first."""
    counts = np.sum(matrices, axis=0)
    wrong = {f"{rows[i]} -> {rows[j]}": int(counts[i, j])
             for i in range(len(rows)) for j in np.flatnonzero(counts[i]) if j != i}
    return dict(sorted(wrong.items(), key=lambda kv: -kv[1])[:k])


def method_report(preds: dict[str, np.ndarray], rows: list[str]) -> dict:
    """Landmark accuracy of one method over test meshes, the truth being landmark i -> landmark i.

    preds: {mesh: (n,) int predicted landmark per template landmark}; rows: the n landmark names.
    Returns {"accuracy": mean over meshes, "per_mesh": {mesh: accuracy}, "confusions": ``top_confusions``,
    "matrices": {mesh: (n,n) 0/1 nested lists}, "frequency": (n,n) float ``frequency_matrix``}.
    """
    n = len(rows)
    mats = [correspondence_matrix(p, n) for p in preds.values()]
    truth = np.arange(n)
    per_mesh = {m: float(accuracy(p, truth)) for m, p in preds.items()}
    return {"accuracy": float(np.mean(list(per_mesh.values()))), "per_mesh": per_mesh,
            "confusions": top_confusions(mats, rows),
            "matrices": {m: mat.astype(int).tolist() for m, mat in zip(preds, mats)},
            "frequency": frequency_matrix(mats)}


DENSE_ERROR_THRESHOLDS = np.linspace(0, 0.25, 51)


def dense_map_summary(errors: np.ndarray) -> dict:
    """Fractions of dense-map errors (p,) (geodesic error / sqrt(area)) within 0.05, 0.10 and 0.25, their mean
    and count."""
    errors = np.asarray(errors)
    return {"within_0.05": float(np.mean(errors <= 0.05)), "within_0.10": float(np.mean(errors <= 0.10)),
            "within_0.25": float(np.mean(errors <= 0.25)), "mean_error": float(errors.mean()),
            "n_points": int(errors.size)}


def numbering_problem(template_F: np.ndarray, target_F: np.ndarray, n_template: int | None = None,
                      n_target: int | None = None) -> str | None:
    """Why vertex ids of the template do not name the same points on a target mesh, or None when they do.

    Two meshes share their vertex numbering only when their triangles are the same (as vertex-id sets, in any
    order; ``same_triangles``): a vertex count says nothing (a file re-exported by another tool often has the
    same count in another order). Pass the faces of the kept component (``corr.mesh``'s "F"), so vertices no
    face uses, e.g. appended by a repair, do not matter. n_template, n_target: vertex counts, for the message.
    """
    if same_triangles(np.asarray(target_F), np.asarray(template_F)):
        return None
    return numbering_reason(len(template_F), len(target_F), n_template, n_target)


def numbering_reason(m_template: int, m_target: int, n_template: int | None = None,
                     n_target: int | None = None) -> str:
    """The text of ``numbering_problem`` from face (m) and vertex (n) counts: the triangles differ."""
    counts = (f"{n_target} vertices / {m_target} faces vs the template's {n_template} / {m_template}"
              if n_template is not None and n_target is not None else
              f"{m_target} faces vs the template's {m_template}")
    same = n_template == n_target and m_template == m_target
    return (f"its triangles are not the template's ({counts}{': same counts, another vertex order' if same else ''})"
            ", so the template's vertex ids do not name the same points on it")


def triangles_problem(template_key: str | None, target_key: str | None, m_template: int, m_target: int,
                      n_template: int | None = None, n_target: int | None = None) -> str | None:
    """``numbering_problem`` from two ``triangles_key`` texts (None: unknown, no objection)."""
    if template_key is None or target_key is None or template_key == target_key:
        return None
    return numbering_reason(m_template, m_target, n_template, n_target)


def scorable_results(results: dict) -> tuple[dict, dict[str, str]]:
    """Split per-mesh method results {mesh: {..., "no_truth": reason?}} into (scorable, {mesh: reason})."""
    skipped = {m: r["no_truth"] for m, r in sorted(results.items()) if r.get("no_truth")}
    return {m: r for m, r in results.items() if m not in skipped}, skipped
