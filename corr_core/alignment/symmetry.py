"""Rotational symmetry about +y read off a shape's own rotation costs C_ii(theta), and an alignment that keeps
symmetric shapes from corrupting the others.

A shape of symmetry order k looks the same turned by 360/k degrees: C_ii(theta) ~= 0 at theta = m V / k
(in view steps, evaluated on the band-limited interpolation, so k need not divide V). Order 1 = no symmetry;
order 0 = the same at every angle (a round table; also reported for order >= V, which V views cannot tell
apart). A pair (i, j) with a k-fold symmetric shape has k equal minima of C_ij: its relative rotation is only
known modulo V/k steps, and such pairs would pull the others toward arbitrary copies.

``place_symmetric``: the solver runs with the kernel of every pair with a symmetric shape divided by its number
of equal minima (so such pairs still count, modulo the symmetry, but cannot outvote the asymmetric pairs); each
symmetric shape is then placed against the shapes already placed (the best total cost), since its own solver
label is only meaningful modulo its symmetry (and for the spectral solver not at all: the first harmonic of a
k-fold periodic kernel vanishes). When every shape is symmetric, the group of the lowest order k is
synchronized first on the k-th harmonic of its kernel (Singer's method on k * angle).
"""
from __future__ import annotations

import numpy as np

from corr_core.alignment.continuous import interpolate_costs
from corr_core.alignment.pair_costs import auto_sigma

__all__ = ["symmetry_orders", "orders_from_self_costs", "symmetry_periods", "downweight_symmetric_pairs", "place_symmetric", "harmonic_sync",
           "place_against"]


def symmetry_orders(C: np.ndarray, scale: float | None = None, *, tolerance: float = 0.05,
                    samples_per_step: int = 4) -> np.ndarray:
    """(N,) int symmetry order of each shape from the diagonal C_ii(theta) of pair costs C: (N, N, V).

    A turn by phi steps counts as a symmetry when the interpolated C_ii(phi) <= tolerance * scale (scale: the
    collection's typical best cost between two different shapes, ``auto_sigma(C)``; the self cost of an
    asymmetric chair at one view step is ~0.4 of it). Order = the largest k in 2..V whose turns m V / k
    (m = 1..k-1) all count; 0 when every phi on a grid of ``samples_per_step`` per step counts; else 1.
    """
    C = np.asarray(C)
    N = C.shape[0]
    scale = auto_sigma(C) if scale is None else float(scale)
    return orders_from_self_costs(C[np.arange(N), np.arange(N)], scale, tolerance=tolerance,
                                  samples_per_step=samples_per_step)


def orders_from_self_costs(self_costs: np.ndarray, scale: float, *, tolerance: float = 0.05,
                           samples_per_step: int = 4, chunk: int = 2048) -> np.ndarray:
    """(N,) int symmetry orders from each shape's self costs C_ii: (N, V) and the collection's cost ``scale``
    (see ``symmetry_orders``, which reads both off a dense C; a candidate graph gives them directly). Rows are
    independent: computed in chunks of ``chunk`` shapes (bounded temporaries at large N)."""
    diag = np.asarray(self_costs)
    N = diag.shape[0]
    if tolerance * float(scale) <= 0:  # every pair of shapes is identical: nothing tells rotations apart
        return np.zeros(N, np.int64)
    return np.concatenate([_orders_of_rows(diag[s:s + chunk].astype(np.float64), tolerance * float(scale),
                                           samples_per_step) for s in range(0, N, chunk)] or [np.zeros(0, np.int64)])


def _orders_of_rows(diag: np.ndarray, threshold: float, samples_per_step: int) -> np.ndarray:
    """Symmetry orders (n,) int of self costs diag: (n, V) float64 at an absolute ``threshold``."""
    N, V = diag.shape
    fine = interpolate_costs(diag, np.broadcast_to(np.arange(V * samples_per_step) / samples_per_step,
                                                    (N, V * samples_per_step)))
    orders = np.where(np.all(fine <= threshold, axis=1), 0, 1)
    for k in range(2, V + 1):
        turns = np.broadcast_to(np.arange(1, k) * V / k, (N, k - 1))
        ok = np.all(interpolate_costs(diag, turns) <= threshold, axis=1)
        orders = np.where((orders != 0) & ok, k, orders)
    return orders.astype(np.int64)


def symmetry_periods(orders: np.ndarray, V: int) -> np.ndarray:
    """(N,) float period in view steps of each shape's rotation: V for order 1, V/k for order k, 0 for 0."""
    k = np.asarray(orders)
    return np.where(k > 0, V / np.maximum(k, 1), 0.0)


def harmonic_sync(C: np.ndarray, k: int, sigma: float) -> np.ndarray:
    """Labels (n,) int for n shapes of symmetry order k from their pair costs C (n, n, V): the top eigenvector of
    H_ij = sum_theta exp(-C_ij(theta)/sigma) exp(i 2 pi k theta / V) gives k x_i modulo V (Singer's angular
    synchronization on the k-th harmonic), so x_i modulo V/k; rounded to whole steps."""
    from corr_core.alignment.sync import sync_matrix
    n, _, V = C.shape
    if n == 1:
        return np.zeros(1, np.int64)
    H = sync_matrix(C, sigma, harmonic=k)
    z = np.linalg.eigh(H)[1][:, -1]
    z = z * np.exp(-1j * np.angle(z[0]))  # fix the eigenvector's global phase: shape 0 at 0
    return np.rint(-np.angle(z) * V / (2 * np.pi * k)).astype(np.int64) % V


def place_against(C: np.ndarray, i: int, placed: np.ndarray, labels: np.ndarray) -> int:
    """Label of shape i that best fits the placed shapes: argmin_theta sum_j C_ij((labels_j - theta) % V)
    (first minimum on ties)."""
    V = C.shape[2]
    theta = np.arange(V)
    total = sum(C[i, j][(labels[j] - theta) % V].astype(np.float64) for j in placed)
    return int(np.argmin(total))


def downweight_symmetric_pairs(C: np.ndarray, orders: np.ndarray, sigma: float) -> np.ndarray:
    """C' (N, N, V) float32: pair costs with the kernel exp(-C'_ij/sigma) of every pair with a symmetric shape
    divided by the number of its equal minima m_ij = max(k_i, k_j) (V for a fully symmetric shape), i.e.
    C'_ij = C_ij + sigma log m_ij; pairs of two asymmetric shapes are unchanged."""
    V = C.shape[2]
    k = np.where(np.asarray(orders) == 0, V, np.asarray(orders)).astype(np.float64)
    minima = np.maximum(k[:, None], k[None, :])
    return (np.asarray(C, np.float64) + (sigma * np.log(minima))[:, :, None]).astype(np.float32)


def place_symmetric(C: np.ndarray, orders: np.ndarray, solve, sigma: float) -> np.ndarray:
    """Labels (N,) int for pair costs C (N, N, V) and symmetry orders (N,) (some != 1).

    solve(costs (N, N, V)) -> labels (N,): the caller's solver. With asymmetric shapes: the solver runs on the
    costs with the symmetric shapes' pairs down-weighted (``downweight_symmetric_pairs``: they still count,
    modulo their symmetry, but cannot outvote the asymmetric pairs), the asymmetric shapes keep its labels, and
    each symmetric shape, by increasing order (fully symmetric ones last), is placed against the shapes placed
    so far (``place_against``), then once more against all the others. Without any: the group of the lowest order k >= 2 is synchronized on the k-th
    harmonic (``harmonic_sync``) and the others are placed against it.
    """
    orders = np.asarray(orders)
    ks = sorted({int(k) for k in orders}, key=lambda k: (k == 0, k))
    if ks[0] == 1:
        labels = np.asarray(solve(downweight_symmetric_pairs(C, orders, sigma)), np.int64).copy()
    else:
        labels = np.zeros(len(orders), np.int64)
        if ks[0] >= 2:
            first = np.flatnonzero(orders == ks[0])
            labels[first] = harmonic_sync(C[np.ix_(first, first)], ks[0], sigma)
    placed = list(np.flatnonzero(orders == ks[0]))
    for k in ks[1:]:
        group = np.flatnonzero(orders == k)
        for i in group:
            labels[i] = place_against(C, i, np.asarray(placed), labels)
        placed.extend(group)
    everyone = np.arange(len(orders))
    for i in np.flatnonzero(orders != ks[0]):  # second pass: against every other shape, now all placed
        labels[i] = place_against(C, i, everyone[everyone != i], labels)
    return labels


def place_against_graph(gc, i: int, placed: np.ndarray, labels: np.ndarray) -> int:
    """``place_against`` on a candidate graph (``graph_costs.GraphCosts`` gc): argmin_theta of
    sum_j C_ij((labels_j - theta) % V) over the graph neighbours j of shape i that are in the boolean mask
    ``placed`` (N,); the current label when none is."""
    V = gc.n_views
    nbrs, costs = gc.neighbor_costs(i)
    use = placed[nbrs]
    if not use.any():
        return int(labels[i])
    theta = np.arange(V)
    idx = (labels[nbrs[use]][:, None] - theta[None, :]) % V
    total = np.take_along_axis(costs[use].astype(np.float64), idx, axis=1).sum(axis=0)
    return int(np.argmin(total))


def _harmonic_sync_graph(gc, k: int, sigma: float) -> np.ndarray:
    """``harmonic_sync`` on a candidate graph: labels (n,) int of n shapes of order k from the top eigenvector
    of the sparse k-th harmonic matrix (Lanczos above ``sync.DENSE_EIGH_MAX`` shapes)."""
    from corr_core.alignment.sync import top_eigenvector
    if gc.n == 1:
        return np.zeros(1, np.int64)
    V = gc.n_views
    z = top_eigenvector(gc.harmonic(sigma, h=k))
    z = z * np.exp(-1j * np.angle(z[0]))
    return np.rint(-np.angle(z) * V / (2 * np.pi * k)).astype(np.int64) % V


def place_symmetric_graph(gc, orders: np.ndarray, solve, sigma: float) -> np.ndarray:
    """``place_symmetric`` on a candidate graph (``graph_costs.GraphCosts`` gc): the same steps with the pairs
    of the graph only (down-weighting per pair, placement against the placed graph neighbours, the k-th
    harmonic of the lowest order's subgraph when no shape is asymmetric). solve(graph costs) -> labels (N,)."""
    orders = np.asarray(orders)
    V = gc.n_views
    ks = sorted({int(k) for k in orders}, key=lambda k: (k == 0, k))
    kk = np.where(orders == 0, V, orders).astype(np.float64)
    minima = np.maximum(kk[gc.rows], kk[gc.cols])
    if ks[0] == 1:
        down = (gc.costs.astype(np.float64) + (sigma * np.log(minima))[:, None]).astype(np.float32)
        labels = np.asarray(solve(gc.with_costs(down)), np.int64).copy()
    else:
        labels = np.zeros(len(orders), np.int64)
        if ks[0] >= 2:
            first = np.flatnonzero(orders == ks[0])
            labels[first] = _harmonic_sync_graph(gc.subgraph(first), ks[0], sigma)
    placed = orders == ks[0]
    for k in ks[1:]:
        group = np.flatnonzero(orders == k)
        for i in group:
            labels[i] = place_against_graph(gc, i, placed, labels)
        placed[group] = True
    everyone = np.ones(len(orders), bool)
    for i in np.flatnonzero(orders != ks[0]):  # second pass: against every other shape, now all placed
        everyone[i] = False
        labels[i] = place_against_graph(gc, i, everyone, labels)
        everyone[i] = True
    return labels
