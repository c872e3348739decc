"""Measures of a joint-alignment solution (all agreements are up to one global offset, see
``corr_core.alignment.azimuth.agreement_up_to_offset``).

A *solution* is the dict of ``corr_core.alignment.solvers.solve_alignment``: names (N,), labels (N,) int,
solver, sigma, seed, knn. Re-solves use the solution's graph (``knn``); energies use the complete graph.
C is a dense (N, N, V) array or, for a candidate graph, a ``corr_core.alignment.graph_costs.GraphCosts``: then
re-solves and energies are on that graph (there is no complete graph), the equivariance check shifts the
graph's (P, V) costs (no copy of an N x N array exists) and the upper bound uses the graph's edges.
"""
from __future__ import annotations

import numpy as np

from corr_core import mrf
from corr_core.alignment import azimuth
from corr_core.alignment.circulant import CirculantPairwise
from corr_core.alignment.graph_costs import GraphCosts
from corr_core.alignment.pair_costs import shift_costs
from corr_core.alignment.solvers import (SOLVERS, knn_neighbors, solve_labels, solve_labels_with_symmetry,
                                        uniform_unary)

__all__ = ["agreement", "seed_stability", "equivariance", "upper_bound", "solver_quality", "ground_truth_agreement",
           "continuous_error", "offset_mean_errors", "periodic_distance", "mode_agreement", "evaluate_alignment"]


def _size(C) -> tuple[int, int]:
    """(N shapes, V views) of dense costs (N, N, V) or graph costs."""
    return (C.n, C.n_views) if isinstance(C, GraphCosts) else (C.shape[0], C.shape[2])


def agreement(a: np.ndarray, b: np.ndarray, V: int) -> dict:
    """Exact and within-one-view agreement of two labelings a, b: (n,) int up to one global offset:
    {"exact": float, "within_one_view": float, "n": int}."""
    return {"exact": float(azimuth.agreement_up_to_offset(a, b, V, tolerance=0)[0]),
            "within_one_view": float(azimuth.agreement_up_to_offset(a, b, V, tolerance=1)[0]), "n": int(len(a))}


def _orders_and_agreement(solution: dict, V: int):
    """(orders (N,) or None, agree(a, b) -> float): agreement up to one offset, modulo each shape's symmetry
    when the solution has symmetric shapes (``agreement_modulo``), else exact (``agreement_up_to_offset``)."""
    orders = solution.get("symmetry_order")
    if orders is None or np.all(np.asarray(orders) == 1):
        return None, lambda a, b: azimuth.agreement_up_to_offset(a, b, V)[0]
    k = np.asarray(orders)
    periods = np.where(k > 0, V / np.maximum(k, 1), 0.0)
    return k, lambda a, b: agreement_modulo(a, b, V, periods)


def seed_stability(C: np.ndarray, solution: dict, seeds: list, op: CirculantPairwise | None = None) -> dict:
    """Agreement (exact up to one offset; modulo each shape's symmetry when some are symmetric) with the
    solution of the labelings from other unary seeds: {"min", "mean", "n_seeds"}. op: the solution graph's
    operator, if already built."""
    labels, V = np.asarray(solution["labels"]), _size(C)[1]
    orders, agree_fn = _orders_and_agreement(solution, V)
    others = [solve_labels_with_symmetry(C, solution["solver"], float(solution["sigma"]), int(s),
                                         int(solution.get("knn", 0)), orders, op)
              for s in seeds if int(s) != solution["seed"]]
    agree = [agree_fn(r, labels) for r in others]
    return {"min": float(min(agree)) if agree else 1.0, "mean": float(np.mean(agree)) if agree else 1.0,
            "n_seeds": len(others) + 1}


def equivariance(C: np.ndarray, solution: dict, shift_seed: int) -> float:
    """Shift every shape's views by a known random offset, solve again: fraction whose label moved by it
    (modulo each shape's symmetry when some are symmetric; shifting views keeps every C_ii, so the orders)."""
    N, V = _size(C)
    shifts = np.random.default_rng(shift_seed).integers(0, V, N)
    orders, agree_fn = _orders_and_agreement(solution, V)
    moved = C.shifted(shifts) if isinstance(C, GraphCosts) else shift_costs(C, shifts)
    shifted = solve_labels_with_symmetry(moved, solution["solver"], float(solution["sigma"]),
                                         int(solution["seed"]), int(solution.get("knn", 0)), orders)
    return float(agree_fn(shifted, (np.asarray(solution["labels"]) + shifts) % V))


def upper_bound(op: CirculantPairwise, unary: np.ndarray) -> float:
    """``mrf.upper_bound`` of the operator; for a sparse (graph) operator the per-pair term is summed over its
    edges (each undirected pair once) instead of an N x N matrix of block maxima."""
    if not op.sparse:
        return float(mrf.upper_bound(op, unary))
    lam = mrf.leading_eigenvalue(op)
    lam += 1e-9 * max(1.0, abs(lam))
    pair_bound = 0.5 * float(op.K_edges.max(axis=1).astype(np.float64).sum())
    return float(np.asarray(unary).max(axis=1).sum() + min(op.n_nodes * lam / 2.0, pair_bound))


def solver_quality(C: np.ndarray, solution: dict, peer_labels: dict, restarts: int, seed: int,
                   op: CirculantPairwise | None = None, *, icm_starts: int = 5) -> dict:
    """Energies on the complete graph (a candidate graph: on that graph) with the solution's unary terms: the
    answer, ICM from ``icm_starts`` random starts (mean; None for 0), the best of ``restarts`` random restarts
    (None for 0), each peer solver's labeling (peer_labels {solver: (N,) int}), a random labeling, and an
    upper bound. op: the complete graph's operator, if already built."""
    N, V = _size(C)
    if op is None:
        op = C.operator(float(solution["sigma"])) if isinstance(C, GraphCosts) else \
            CirculantPairwise(C, float(solution["sigma"]))
    unary = uniform_unary(N, V, seed=int(solution["seed"]))
    rng = np.random.default_rng(seed)
    energy = lambda lab: float(mrf.energy(op, unary, lab))  # noqa: E731
    icm = [energy(mrf.icm(op, unary, mrf.random_labels(N, V, rng))) for _ in range(icm_starts)]
    quality = {"energy": energy(np.asarray(solution["labels"])),
               "icm_random_start_mean": float(np.mean(icm)) if icm else None,
               "best_of_random_restarts": float(mrf.best_of_random_restarts(op, unary, restarts, seed=seed)[1])
               if restarts else None,
               "upper_bound": upper_bound(op, unary),
               "random_labeling": energy(mrf.random_labels(N, V, rng))}
    quality.update({f"energy_{peer}": energy(lab) for peer, lab in peer_labels.items()})
    return quality


def periodic_distance(x: np.ndarray, period: np.ndarray) -> np.ndarray:
    """|x| modulo period (elementwise, broadcasting), in [0, period/2]; 0 where period is 0 (any value fits)."""
    p = np.where(period > 0, period, 1.0)
    return np.where(period > 0, np.abs((x + 0.5 * p) % p - 0.5 * p), 0.0)


def agreement_modulo(a: np.ndarray, b: np.ndarray, V: int, periods: np.ndarray, *, tolerance: int = 0) -> float:
    """Fraction of items with labels a == b + offset modulo their period (periods (n,) float steps: V for an
    asymmetric shape, V/k for a k-fold symmetric one, 0 = any label fits), best over global offsets 0..V-1."""
    d = np.asarray(a, np.float64)[None, :] - np.asarray(b, np.float64)[None, :] - np.arange(V)[:, None]
    return float((periodic_distance(d, np.asarray(periods, np.float64)[None, :]) <= tolerance + 1e-9)
                 .mean(axis=1).max()) if len(a) else 1.0


# Differences per block of ``offset_mean_errors`` (512 kB: its elementwise steps stay in cache).
# `python bench/continuous_error.py` printed, against one offset at a time (the code before), x0.06 of its time at
# 98 shapes, x0.31 at 1,000, x0.63 at 10,000 (64 MB blocks: x1.46, x0.57, x1.37), the same means bit for bit.
OFFSET_BLOCK_VALUES = 1 << 16


def offset_mean_errors(diff: np.ndarray, period: np.ndarray, offsets: np.ndarray, *,
                       block_values: int = OFFSET_BLOCK_VALUES) -> np.ndarray:
    """Mean ``periodic_distance(diff - o, period)`` for every offset o: diff, period (n,) float, offsets (m,) float
    -> (m,) float. A block of offsets of about ``block_values`` differences at a time ((m, n) at once would be 2.9 GB
    for the 36,000 offsets of ``continuous_error`` at n = 10,000); every block size gives the same means bit for
    bit."""
    step = max(1, block_values // max(1, diff.size))
    return np.concatenate([periodic_distance(diff[None, :] - offsets[s:s + step, None], period[None, :]).mean(axis=1)
                           for s in range(0, len(offsets), step)])


def continuous_error(angles_deg: np.ndarray, truth_deg: np.ndarray, orders: np.ndarray | None = None,
                     *, resolution_deg: float = 0.01) -> dict:
    """Error in degrees of continuous azimuths (n,) against true ones (n,), up to one global offset (the one
    minimising the mean error, on a grid of ``resolution_deg``), each modulo 360/k for a shape of symmetry
    order k (orders (n,) int; 0 = fully symmetric: left out). {"mean_error_deg", "max_error_deg",
    "offset_deg", "n"} (n = shapes counted)."""
    orders = np.ones(len(angles_deg), np.int64) if orders is None else np.asarray(orders)
    keep = orders != 0
    period = 360.0 / np.maximum(orders[keep], 1)
    diff = np.asarray(angles_deg, np.float64)[keep] - np.asarray(truth_deg, np.float64)[keep]
    if not keep.any():
        return {"mean_error_deg": 0.0, "max_error_deg": 0.0, "offset_deg": 0.0, "n": 0}
    offsets = np.arange(0.0, 360.0, resolution_deg)
    means = offset_mean_errors(diff, period, offsets)
    best = int(np.argmin(means))
    err = periodic_distance(diff - offsets[best], period)
    return {"mean_error_deg": float(err.mean()), "max_error_deg": float(err.max()),
            "offset_deg": float(offsets[best]), "n": int(keep.sum())}


def ground_truth_agreement(names: list[str], labels: np.ndarray, truth: dict[str, int], V: int,
                           peer_labels: dict | None = None, angles_deg: np.ndarray | None = None,
                           truth_deg: dict[str, float] | None = None,
                           orders: np.ndarray | None = None) -> dict:
    """Agreement of labels (N,) with known azimuth steps truth {name: steps} on the shapes that have one, and
    the exact agreement of each peer solver's labels ("exact_<solver>").

    orders (N,) int symmetry orders (None = all 1): when some shape is symmetric, exact / within-one-view are
    counted modulo each shape's symmetry (``agreement_modulo``). With angles_deg (N,) and truth_deg
    {name: degrees}: the continuous error (``continuous_error``) as mean_error_deg, max_error_deg (and the
    global offset_deg: angles ~= truth + offset), the
    mean error of the labels' own angles (labels_mean_error_deg) for comparison, and nearest_view_exact: the
    fraction of labels equal to the nearest view of the true azimuth turned into the solution's frame by the
    continuous offset (with continuous truths "exact" depends on where a whole-step offset puts the rounding
    cuts; this does not).
    """
    common = [i for i, n in enumerate(names) if n in truth]
    steps = np.array([truth[names[i]] for i in common])
    k = None if orders is None else np.asarray(orders)[common]
    if k is None or np.all(k == 1):
        out = agreement(labels[common], steps, V)
        for p, lab in (peer_labels or {}).items():
            out[f"exact_{p}"] = agreement(lab[common], steps, V)["exact"]
    else:
        periods = np.where(k > 0, V / np.maximum(k, 1), 0.0)
        out = {"exact": agreement_modulo(labels[common], steps, V, periods),
               "within_one_view": agreement_modulo(labels[common], steps, V, periods, tolerance=1), "n": len(common),
               "modulo_symmetry": True}
        for p, lab in (peer_labels or {}).items():
            out[f"exact_{p}"] = agreement_modulo(lab[common], steps, V, periods)
    if angles_deg is not None and truth_deg:
        both = [i for i in common if names[i] in truth_deg]
        true = np.array([truth_deg[names[i]] for i in both])
        kk = None if orders is None else np.asarray(orders)[both]
        cont = continuous_error(np.asarray(angles_deg)[both], true, kk)
        nearest = np.rint((true + cont["offset_deg"]) * V / 360.0).astype(np.int64) % V  # in the solution's frame
        kp = np.ones(len(both)) * V if kk is None else np.where(kk > 0, V / np.maximum(kk, 1), 0.0)
        d = periodic_distance(labels[both].astype(np.float64) - nearest, kp)
        out.update(mean_error_deg=cont["mean_error_deg"], max_error_deg=cont["max_error_deg"],
                   offset_deg=cont["offset_deg"], labels_mean_error_deg=continuous_error(labels[both] * 360.0 / V, true, kk)["mean_error_deg"],
                   nearest_view_exact=float(np.mean(d < 1e-9)) if both else 1.0)
    return out


def mode_agreement(names: list[str], labels: np.ndarray, other: dict, V: int) -> dict | None:
    """Agreement with another run's solution {"names", "labels"} (e.g. meshes vs pre-rendered views) on the
    shapes both hold; None when they share no shape."""
    other_map = dict(zip(other["names"], np.asarray(other["labels"])))
    common = [i for i, n in enumerate(names) if n in other_map]
    if not common:
        return None
    return agreement(labels[common], np.array([other_map[names[i]] for i in common]), V)


def _continuous_fields(names: list[str], solution: dict) -> dict:
    """{"angles_deg": {name: float}, "symmetry_order": {name: int}} of a solution that has them (else {})."""
    out = {}
    if solution.get("angles_deg") is not None:
        out["angles_deg"] = {n: float(a) for n, a in zip(names, np.asarray(solution["angles_deg"]))}
    if solution.get("symmetry_order") is not None:
        out["symmetry_order"] = {n: int(k) for n, k in zip(names, np.asarray(solution["symmetry_order"]))}
    return out


def evaluate_alignment(C: np.ndarray, solution: dict, truth: dict[str, int] | None = None,
                       other: dict | None = None, seeds: list = (0, 1, 2, 3, 4), *, shift_seed: int = 123,
                       restarts: int = 20, compare_solvers: bool = True,
                       truth_deg: dict[str, float] | None = None, truth_orders: dict[str, int] | None = None,
                       icm_starts: int = 5) -> dict:
    """All measures of an alignment solution of pair costs C: (N, N, V) (float32 as stored; the operators
    compute in float64).

    - labels {name: view index} and angle_deg (the label's angle); angles_deg {name: continuous degrees} and
      symmetry_order {name: k} (1 none, 0 every angle) when the solution has them;
    - seed_stability: agreement of the labelings from several unary seeds with the first;
    - equivariance: shift each shape's views by known random offsets, solve again, fraction whose label moved
      by exactly that offset;
    - agreement_with peers and solver_quality: energies of the answer, ICM from random starts, best of random
      restarts, each solver (lh, spectral, ppm when ``compare_solvers``), a random labeling, an upper bound;
    - ground_truth (truth {name: steps}, e.g. generated data): fraction exact and within one view (per solver),
      modulo each shape's symmetry (truth_orders {name: k} if given, else the detected orders); with truth_deg
      {name: degrees} the continuous mean_error_deg / max_error_deg; symmetry_detected: fraction of shapes
      whose detected order equals truth_orders;
    - mode_agreement with another run's solution on common shapes;
    - on a candidate graph (C a GraphCosts): graph "candidates", pairs_computed (P), pairs_total (N(N-1)/2)
      and pairs_fraction.
    """
    names, labels = list(solution["names"]), np.asarray(solution["labels"])
    sigma = float(solution["sigma"])
    if isinstance(C, GraphCosts):
        N, V = C.n, C.n_views
        graph_op = full_op = C.operator(sigma)                                        # the candidate graph
        pairs = {"graph": "candidates", "pairs_computed": C.n_pairs, "pairs_total": N * (N - 1) // 2,
                 "pairs_fraction": C.n_pairs / max(1, N * (N - 1) // 2)}
    else:
        C = np.asarray(C)
        N, _, V = C.shape
        neighbors = knn_neighbors(C, int(solution.get("knn", 0)))
        graph_op = CirculantPairwise(C, sigma, neighbors)                             # the solution's graph
        full_op = graph_op if neighbors is None else CirculantPairwise(C, sigma)      # energies, peers
        pairs = {}
    m: dict = {"n_shapes": N, "n_views": V, "solver": solution["solver"], "sigma": sigma, **pairs,
               "labels": {n: int(l) for n, l in zip(names, labels)},
               "angle_deg": {n: float(l * 360.0 / V) for n, l in zip(names, labels)},
               **_continuous_fields(names, solution),
               "seed_stability": seed_stability(C, solution, list(seeds), graph_op),
               "equivariance": equivariance(C, solution, shift_seed)}
    peers = {}
    if compare_solvers:
        peers = {p: labels if p == solution["solver"] else
                 solve_labels(C, p, sigma, int(solution["seed"]), op=full_op)["labels"] for p in SOLVERS}
        m["agreement_with"] = {p: float(azimuth.agreement_up_to_offset(lab, labels, V)[0])
                               for p, lab in peers.items() if p != solution["solver"]}
    m["solver_quality"] = solver_quality(C, solution, peers, restarts, shift_seed, full_op, icm_starts=icm_starts)
    if truth:
        detected = solution.get("symmetry_order")
        orders = (np.array([truth_orders.get(n, 1) for n in names]) if truth_orders else
                  None if detected is None else np.asarray(detected))
        angles = solution.get("angles_deg")
        m["ground_truth"] = ground_truth_agreement(names, labels, truth, V, peers,
                                                   None if angles is None else np.asarray(angles), truth_deg, orders)
        if truth_orders and detected is not None:
            m["ground_truth"]["symmetry_detected"] = float(np.mean(
                [int(k) == int(truth_orders[n]) for n, k in zip(names, detected) if n in truth_orders]))
    if other is not None:
        modes = mode_agreement(names, labels, other, V)
        if modes is not None:
            m["mode_agreement"] = modes
    return m
