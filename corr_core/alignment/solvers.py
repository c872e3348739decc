"""Solving the joint-alignment MRF: labels x (N,) in 0..V-1 from pair costs C: (N, N, V).

The MRF (conventions in ``corr_core.alignment.pair_costs``): pairwise W_ij(t1, t2) = exp(-Csym_ij(t2-t1)/sigma)
(``corr_core.alignment.circulant.CirculantPairwise``), unary terms i.i.d. uniform in [0, 1) from a seed
(``uniform_unary``: they only break the global-rotation tie). Three solvers of the same energy:

- ``"lh"``: Leordeanu & Hebert's spectral relaxation + climbing (``corr_core.mrf.solve_lh``);
- ``"spectral"``: angular synchronization (``corr_core.alignment.sync.spectral_sync_operator``);
- ``"ppm"``: Chen & Candes' projected power method (``corr_core.alignment.sync.projected_power``).

C is either a dense (N, N, V) array (the complete graph, optionally restricted to a kNN graph by ``knn``) or a
``corr_core.alignment.graph_costs.GraphCosts`` (the pairs of a candidate graph only; the same solvers on the
sparse operator of that graph, nothing of size N^2).

``solve_alignment`` also detects each shape's rotational symmetry (``corr_core.alignment.symmetry``; symmetric
shapes are placed without steering the others) and refines the labels to continuous angles
(``corr_core.alignment.continuous``).
"""
from __future__ import annotations

import numpy as np

from corr_core import mrf
from corr_core.alignment import continuous, symmetry, sync
from corr_core.alignment.circulant import CirculantPairwise
from corr_core.alignment.graph_costs import GraphCosts
from corr_core.alignment.pair_costs import auto_sigma, nearest_shapes

__all__ = ["SOLVERS", "uniform_unary", "choose_sigma", "knn_neighbors", "solve_labels", "solve_labels_with_symmetry",
           "solve_alignment",
           "solution_angles_deg"]

SOLVERS = ("lh", "spectral", "ppm")


def uniform_unary(n: int, V: int, *, seed: int | None = 0) -> np.ndarray:
    """(n, V) i.i.d. uniform [0, 1) unary terms (they break the global-rotation tie of the pairwise term)."""
    return np.random.default_rng(seed).uniform(0.0, 1.0, size=(n, V))


def choose_sigma(C: np.ndarray, sigma: float | str | None = "auto", *, sigma_scale: float = 1.0) -> float:
    """Kernel width: ``auto_sigma(C)`` (median over pairs of min_theta C_ij; ``GraphCosts.auto_sigma`` on a
    candidate graph) for sigma None/"auto", else float(sigma); times sigma_scale. Units of C."""
    if sigma in (None, "auto"):
        base = C.auto_sigma() if isinstance(C, GraphCosts) else auto_sigma(C)
    else:
        base = float(sigma)
    return float(base * sigma_scale)


def knn_neighbors(C: np.ndarray, knn: int) -> np.ndarray | None:
    """(N, knn) int nearest shapes of each shape (``nearest_shapes``), or None for the complete graph
    (knn 0, or knn >= N - 1)."""
    return nearest_shapes(C, knn) if knn and knn < len(C) - 1 else None


def solve_labels(C: np.ndarray, solver: str, sigma: float, seed: int, *, knn: int = 0,
                 op: CirculantPairwise | None = None) -> dict:
    """Labels (N,) for pair costs C (N,N,V) with the chosen solver, plus energy diagnostics.

    Returns {"labels": (N,) int64, "energy": float (on the graph of ``knn``)} and, for "lh", iterations,
    converged, relaxed_value, energy_before_climb. op: the MRF operator of (C, sigma, knn) when the caller
    already built it (its kernel is N*N*V exps).
    """
    if isinstance(C, GraphCosts):
        _check_graph_knn(knn)
        N, V, neighbors = C.n, C.n_views, None
        op = C.operator(sigma) if op is None else op
    else:
        N, _, V = C.shape
        neighbors = knn_neighbors(C, knn)
        if op is None:
            op = CirculantPairwise(C, sigma, neighbors)
    unary = uniform_unary(N, V, seed=seed)
    out: dict = {}
    if solver == "lh":
        res = mrf.solve_lh(op, unary, compute_bound=False)
        labels = res.labels
        out.update(iterations=int(res.iterations), converged=bool(res.converged),
                   relaxed_value=float(res.relaxed_value), energy_before_climb=float(res.energy_before_climb))
    elif solver == "spectral":
        labels = sync.spectral_sync_operator(op)  # same as sync.spectral_sync(C, sigma, neighbors), one kernel
    elif solver == "ppm" and isinstance(C, GraphCosts):
        labels, _ = sync.projected_power_operator(_centered_kernel(op), sync.spectral_sync_operator(op))
    elif solver == "ppm":
        labels, _ = sync.projected_power(C, sigma, neighbors=neighbors)
    else:
        raise ValueError(f"unknown solver '{solver}' (use lh, spectral or ppm)")
    labels = np.asarray(labels, dtype=np.int64)
    out.update(labels=labels, energy=float(mrf.energy(op, unary, labels)))
    return out


def _check_graph_knn(knn: int) -> None:
    if knn:
        raise ValueError(f"knn = {knn}: the costs are on a candidate graph already (sparse); knn applies to the "
                         f"complete graph only: use knn 0 with candidate pairs")


def _centered_kernel(op: CirculantPairwise) -> CirculantPairwise:
    """The sparse operator of op's kernels, each centred over theta (projected power's debiased scores)."""
    S = op.K_edges.astype(np.float64)
    return CirculantPairwise.from_edges(op.indptr, op.indices, S - S.mean(axis=1, keepdims=True))


def solve_labels_with_symmetry(C: np.ndarray, solver: str, sigma: float, seed: int, knn: int,
                               orders: np.ndarray | None, op: CirculantPairwise | None = None) -> np.ndarray:
    """Labels (N,) int as ``solve_alignment`` makes them for known symmetry orders (N,) int: ``solve_labels``
    when no shape is symmetric (orders None or all 1; op: its operator, if built), else
    ``symmetry.place_symmetric`` around the same solver."""
    if orders is None or np.all(np.asarray(orders) == 1):
        return solve_labels(C, solver, sigma, seed, knn=knn, op=op)["labels"]
    if isinstance(C, GraphCosts):
        return symmetry.place_symmetric_graph(C, np.asarray(orders),
                                              lambda g: solve_labels(g, solver, sigma, seed)["labels"], sigma)
    return symmetry.place_symmetric(C, np.asarray(orders),
                                    lambda Cw: solve_labels(Cw, solver, sigma, seed, knn=knn)["labels"], sigma)


def solve_alignment(C: np.ndarray, solver: str = "lh", sigma: float | str = "auto", *, sigma_scale: float = 1.0,
                    seed: int = 0, knn: int = 0, symmetric: bool = True) -> dict:
    """Joint alignment of N shapes from pair costs C: (N, N, V) (float32 is kept: no float64 copy).

    Returns ``solve_labels``' dict plus sigma, solver, seed, n_views, knn, and
    - symmetry_order (N,) int: each shape's rotational symmetry order from C_ii (``symmetry.symmetry_orders``;
      1 = none, 0 = every angle);
    - angles_deg (N,) float in [0, 360): continuous azimuths (``continuous.refine_labels``: the labels refined
      on the band-limited C_ij, defined modulo 360/k for a k-fold symmetric shape; round(angle / step) is
      the label up to rounding at half steps).
    With ``symmetric`` and some shape symmetric (order != 1), the labels come from ``symmetry.place_symmetric``
    (the solver on costs whose symmetric pairs are down-weighted, then each symmetric shape placed against the
    others) and energy is that labeling's on the original costs; when no shape is symmetric the labels are
    exactly the solver's.
    Raises ValueError when C holds NaN or inf (a shape's features are broken).
    """
    if isinstance(C, GraphCosts):
        return _solve_alignment_graph(C, solver, sigma, sigma_scale, seed, knn, symmetric)
    C = np.asarray(C)
    if not np.all(np.isfinite(C.min(axis=2))):  # min propagates NaN/inf; avoids an (N, N, V) bool temporary
        raise ValueError("pair costs contain NaN: a shape's features are broken")
    s = choose_sigma(C, sigma, sigma_scale=sigma_scale)
    N, _, V = C.shape
    orders = symmetry.symmetry_orders(C) if symmetric else np.ones(N, np.int64)  # scale: auto_sigma(C)
    if np.any(orders != 1):
        labels = solve_labels_with_symmetry(C, solver, s, seed, knn, orders)
        op = CirculantPairwise(C, s, knn_neighbors(C, knn))
        out = {"labels": labels, "energy": float(mrf.energy(op, uniform_unary(N, V, seed=seed), labels))}
    else:
        out = solve_labels(C, solver, s, seed, knn=knn)
    t = continuous.refine_labels(C, out["labels"], s, symmetry.symmetry_periods(orders, V))
    out.update(sigma=s, solver=solver, seed=seed, n_views=int(V), knn=int(knn),
               symmetry_order=orders, angles_deg=continuous.steps_to_degrees(t, V))
    return out


def _solve_alignment_graph(gc: GraphCosts, solver: str, sigma, sigma_scale: float, seed: int, knn: int,
                           symmetric: bool) -> dict:
    """``solve_alignment`` on candidate-graph costs: the same steps with the graph's sparse operator, symmetry
    orders from the self costs (all 1 when they were not computed), continuous angles refined on the graph's
    pairs (``continuous.refine_labels_graph``). Adds pairs_computed (P off-diagonal pairs)."""
    _check_graph_knn(knn)
    if not np.all(np.isfinite(gc.best())):
        raise ValueError("pair costs contain NaN: a shape's features are broken")
    s = choose_sigma(gc, sigma, sigma_scale=sigma_scale)
    N, V = gc.n, gc.n_views
    use_symmetry = symmetric and gc.self_costs is not None
    orders = symmetry.orders_from_self_costs(gc.self_costs, gc.auto_sigma()) if use_symmetry else np.ones(N, np.int64)
    op = gc.operator(s)
    if np.any(orders != 1):
        labels = solve_labels_with_symmetry(gc, solver, s, seed, 0, orders)
        out = {"labels": labels, "energy": float(mrf.energy(op, uniform_unary(N, V, seed=seed), labels))}
    else:
        out = solve_labels(gc, solver, s, seed, op=op)
    del op
    t = continuous.refine_labels_graph(N, gc.rows, gc.cols, gc.costs, out["labels"], s,
                                       symmetry.symmetry_periods(orders, V))
    out.update(sigma=s, solver=solver, seed=seed, n_views=int(V), knn=0, graph="candidates",
               pairs_computed=gc.n_pairs, symmetry_order=orders, angles_deg=continuous.steps_to_degrees(t, V))
    return out


def solution_angles_deg(solution: dict) -> np.ndarray:
    """(N,) float degrees of a solution: its continuous ``angles_deg``, or label * 360 / n_views when it has
    none (a solution made before continuous azimuths)."""
    if solution.get("angles_deg") is not None:
        return np.asarray(solution["angles_deg"], dtype=np.float64)
    return np.asarray(solution["labels"], dtype=np.float64) * 360.0 / int(solution["n_views"])
