"""Measures of dense maps and transferred landmarks (Kim, Lipman & Funkhouser 2011 protocol).

Every error is a geodesic distance on the *target* (heat method, ``corr_core.geometry.geodesic``) divided by
sqrt(target surface area). One heat solve per evaluated vertex is shared by every map evaluated together.
"""
from __future__ import annotations

import numpy as np

from corr_core.geometry.geodesic import GeodesicSolver
from corr_core.geometry.primitives import face_areas

KIM_THRESHOLDS = np.linspace(0.0, 0.25, 51)


def dense_errors(V_target: np.ndarray, F_target: np.ndarray, maps: dict, true_map: np.ndarray,
                 vertices: np.ndarray | None = None, solver: GeodesicSolver | None = None) -> dict:
    """Geodesic error / sqrt(area) of several dense maps at the same template vertices.

    Args:
        V_target: (n_t,3) float; F_target: (m_t,3) int.
        maps: {name: (n_s,) int target vertex of every template vertex}.
        true_map: (n_s,) int the correct target vertex of every template vertex (identity for same meshes).
        vertices: (p,) int template vertices to evaluate (default all; e.g. >= 2000 farthest-point samples).
        solver: optional ``GeodesicSolver`` of the target, reused.
    Returns: {name: (p,) float errors}.
    """
    true_map = np.asarray(true_map, dtype=np.int64)
    vertices = np.arange(len(true_map)) if vertices is None else np.asarray(vertices, dtype=np.int64)
    for name, m in maps.items():
        if len(m) != len(true_map):
            raise ValueError(f"map {name!r} has {len(m)} entries, the ground truth {len(true_map)}")
    solver = GeodesicSolver(V_target, F_target) if solver is None else solver
    scale = np.sqrt(face_areas(np.asarray(V_target, float), np.asarray(F_target)).sum())
    pred = {name: np.asarray(m, dtype=np.int64)[vertices] for name, m in maps.items()}
    out = {name: np.zeros(len(vertices)) for name in maps}
    truth = true_map[vertices]
    for t in np.unique(truth):                         # one heat solve per distinct true target vertex
        rows = np.flatnonzero(truth == t)
        d = solver.distance(int(t))
        for name in maps:
            out[name][rows] = d[pred[name][rows]]
    for name in maps:
        out[name] = np.where(pred[name] == truth, 0.0, out[name]) / scale
    return out


def kim_curve(errors: np.ndarray, thresholds: np.ndarray = KIM_THRESHOLDS) -> np.ndarray:
    """Fraction of errors <= each threshold: (p,) float, (T,) -> (T,) float, non-decreasing."""
    err = np.sort(np.asarray(errors, dtype=np.float64).ravel())
    if err.size == 0:
        raise ValueError("no errors given")
    return np.searchsorted(err, np.asarray(thresholds, dtype=np.float64), side="right") / err.size


def summary(errors: np.ndarray) -> dict:
    """{"mean_error", "within_0.05", "within_0.10", "within_0.25"} of (p,) normalized errors."""
    e = np.asarray(errors, dtype=np.float64)
    return {"mean_error": float(e.mean()), "within_0.05": float(np.mean(e <= 0.05)),
            "within_0.10": float(np.mean(e <= 0.10)), "within_0.25": float(np.mean(e <= 0.25))}


def landmark_errors(V_target: np.ndarray, F_target: np.ndarray, transferred: np.ndarray, true_landmarks: np.ndarray,
                    solver: GeodesicSolver | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Transfer error and nearest true landmark of each transferred landmark.

    Args:
        transferred: (L,) int target vertices placed for the template landmarks (in the template's order).
        true_landmarks: (L,) int the target's true landmark vertices, same order (same names).
    Returns:
        errors: (L,) float geodesic distance / sqrt(area) from the placed to the true vertex.
        nearest: (L,) int index of the true landmark geodesically nearest to each placed one.
    """
    transferred = np.asarray(transferred, dtype=np.int64)
    true_landmarks = np.asarray(true_landmarks, dtype=np.int64)
    if transferred.shape != true_landmarks.shape:
        raise ValueError(f"{len(transferred)} transferred landmarks but {len(true_landmarks)} true ones")
    solver = GeodesicSolver(V_target, F_target) if solver is None else solver
    scale = np.sqrt(face_areas(np.asarray(V_target, float), np.asarray(F_target)).sum())
    D = solver.distances(true_landmarks)[:, transferred] / scale          # (L true, L placed)
    return np.diag(D).copy(), np.argmin(D, axis=0)


def landmark_accuracy(nearest: np.ndarray) -> float:
    """Fraction of transferred landmarks whose nearest true landmark has their name: nearest (L,) int -> float."""
    nearest = np.asarray(nearest)
    return float(np.mean(nearest == np.arange(len(nearest))))
