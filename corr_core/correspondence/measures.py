"""Evaluating correspondences: landmark accuracy, confusion/frequency matrices, geodesic error curves.

Dense-map measure of Kim, Lipman & Funkhouser 2011 (Blended Intrinsic Maps): for each evaluated point, the
geodesic distance on the target surface between the predicted and the true image, divided by sqrt(area of
the target surface); a curve reports the fraction of points whose error is <= each threshold in 0..0.25.
"""
from __future__ import annotations

import numpy as np


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


def plot_frequency_matrix(freq: np.ndarray, names_rows, names_cols, title: str, path) -> None:
    """Save a heat map of a (n,L) frequency matrix with names on both axes (PNG or PDF by extension)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n, L = freq.shape
    fig, ax = plt.subplots(figsize=(2.0 + 0.38 * L, 1.5 + 0.34 * n))
    im = ax.imshow(freq, cmap="viridis", vmin=0.0, vmax=max(1.0, float(freq.max())), aspect="equal")
    ax.set_xticks(range(L), labels=list(names_cols), rotation=60, ha="right", fontsize=8)
    ax.set_yticks(range(n), labels=list(names_rows), fontsize=8)
    ax.set_xlabel("test landmark (label)")
    ax.set_ylabel("template landmark")
    for i, a in zip(*np.nonzero(freq)):
        ax.text(a, i, f"{freq[i, a]:.2f}".lstrip("0"), ha="center", va="center", fontsize=6,
                color="black" if freq[i, a] > 0.6 else "white")
    ax.set_title(title)
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="fraction of test meshes")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


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


def plot_error_curves(curves: dict, path, title: str = "Geodesic error (Kim et al. 2011)") -> None:
    """Save cumulative error curves. curves: {label: (thresholds (T,), fractions (T,))}."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.2))
    colors = plt.get_cmap("tab10" if len(curves) <= 10 else "tab20")
    for c, (label, (thr, frac)) in enumerate(curves.items()):
        ax.plot(thr, 100 * np.asarray(frac), label=label, lw=1.8, color=colors(c % colors.N),
                ls="-" if c < 10 else "--")
    ax.set_xlabel("geodesic error / sqrt(area)")
    ax.set_ylabel("% correspondences")
    ax.set_ylim(0, 100)
    ax.set_xlim(0, max(float(np.max(t)) for t, _ in curves.values()))
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def surface_area(V: np.ndarray, F: np.ndarray) -> float:
    """Total triangle area (length^2). V: (n,3); F: (m,3)."""
    return float(0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum())


def geodesic_errors(V: np.ndarray, F: np.ndarray, pred_vids, true_vids) -> np.ndarray:
    """Kim–Lipman–Funkhouser error of predicted vertex images on the target mesh (V, F).

    Args: pred_vids, true_vids: (p,) int vertex ids on the target. Returns: (p,) float, geodesic distance
    (heat method) between predicted and true vertex divided by sqrt(surface area); dimensionless.
    """
    from corr_core.geometry.geodesic import _solver

    pred_vids = np.asarray(pred_vids, dtype=np.int64)
    true_vids = np.asarray(true_vids, dtype=np.int64)
    solver = _solver(V, F)
    err = np.zeros(len(pred_vids))
    wrong = pred_vids != true_vids
    for t in np.unique(true_vids[wrong]):  # one heat solve per distinct true vertex
        rows = np.flatnonzero(wrong & (true_vids == t))
        err[rows] = solver.compute_distance(int(t))[pred_vids[rows]]
    return err / np.sqrt(surface_area(V, F))
