"""One-to-one assignment between two point sets from a cost matrix."""
from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment


def hungarian_match(cost: np.ndarray) -> np.ndarray:
    """Minimum-cost one-to-one assignment (Hungarian / Jonker–Volgenant via scipy).

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
    rows, cols = linear_sum_assignment(cost)
    match = np.empty(cost.shape[0], dtype=np.int64)
    match[rows] = cols
    return match
