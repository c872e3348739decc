"""One-to-one assignment between two point sets from a cost matrix."""
from __future__ import annotations

import zlib

import numpy as np
from scipy.optimize import linear_sum_assignment


TIE_QUANTUM = 1e-6     # costs closer than this fraction of the largest |cost| are ties (eigensolver noise is ~1e-12)


def tie_broken_cost(cost: np.ndarray) -> np.ndarray:
    """The assignment problem of ``cost`` with one optimum, whatever the floating-point noise in it.

    Costs are rounded to ``TIE_QUANTUM`` of the largest |cost| (as whole quanta), so assignments that differ
    only by noise (e.g. the two sides of a symmetric shape, whose last digits a library update moves) tie
    exactly; a pseudo-random jitter of less than one quantum over a whole assignment then separates every tie, so
    no solver's scan order (which could favour the input's own order, on landmarks the answer) decides it. The
    jitter is seeded by the rounded costs themselves: the same problem gets the same answer on any machine, and
    different problems (e.g. the poses of one symmetric template) are not all tipped the same way.

    Args:
        cost: (a,b) float. Returns: (a,b) float, in quanta.
    """
    scale = float(np.max(np.abs(cost), initial=0.0)) or 1.0
    quanta = np.round(cost / (scale * TIE_QUANTUM))
    jitter = np.random.default_rng(zlib.crc32(quanta.tobytes())).random(cost.shape)
    return quanta + jitter / (cost.shape[0] + 1)      # a rows: less than one quantum over an assignment


def hungarian_match(cost: np.ndarray) -> np.ndarray:
    """Minimum-cost one-to-one assignment (Hungarian / Jonker–Volgenant via scipy) of ``tie_broken_cost``: the
    same on any machine, ties broken by a jitter seeded by the costs.

    Args:
        cost: (a,b) float, a <= b; cost[i, j] = cost of matching source i to target j.
    Returns:
        (a,) int: target index of every source row; all distinct.
    """
    cost = np.asarray(cost, dtype=np.float64)
    if cost.ndim != 2:
        raise ValueError(f"cost must be 2-D, got shape {cost.shape}")
    if cost.shape[0] > cost.shape[1]:
        raise ValueError(f"more sources than targets ({cost.shape}): a one-to-one match is impossible")
    if not np.all(np.isfinite(cost)):
        raise ValueError("cost contains NaN or inf")
    rows, cols = linear_sum_assignment(tie_broken_cost(cost))
    match = np.empty(cost.shape[0], dtype=np.int64)
    match[rows] = cols
    return match
