"""A candidates stage's result (``candidates: STAGE``): checked, and made the canonical pairs a pair stage runs on."""
from __future__ import annotations

import numpy as np

CANDIDATES_FORMAT = "{'names': [M item names], 'pairs': (P, 2) integer indices into names, i != j}"


def candidate_pairs(value, items: list[str], over: str) -> np.ndarray:
    """The candidate pairs a candidates stage returned, checked and made canonical.

    value: ``{"names": [M names], "pairs": (P, 2) int}`` (other keys ignored); items: the N sorted item names of
    the paired stage ``over``. Returns (P', 2) int64 indices into ``items``, each row (lo, hi) with lo < hi,
    rows sorted and unique ((i, j) and (j, i) are one pair). Raises ValueError saying what is wrong.
    """
    if not isinstance(value, dict) or "names" not in value or "pairs" not in value:
        got = f"a dict with keys {sorted(value)}" if isinstance(value, dict) else f"a {type(value).__name__}"
        raise ValueError(f"it returned {got}, not a dict with the keys 'names' and 'pairs'")
    position = {n: i for i, n in enumerate(items)}
    to_item = np.array([position[n] for n in _checked_names(value["names"], position, over)], dtype=np.int64)
    pairs = _checked_pairs(value["pairs"], len(to_item))
    if not len(pairs):
        return np.zeros((0, 2), dtype=np.int64)
    global_pairs = to_item[pairs]
    canonical = np.stack([global_pairs.min(axis=1), global_pairs.max(axis=1)], axis=1)
    return np.unique(canonical, axis=0).astype(np.int64).reshape(-1, 2)


def _checked_names(names, position: dict[str, int], over: str) -> list[str]:
    """The candidates' ``names`` as a list: distinct item names of ``over`` (ValueError otherwise)."""
    names = names.tolist() if isinstance(names, np.ndarray) else names
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
        raise ValueError("'names' must be a list of item names (str)")
    if len(set(names)) != len(names):
        seen: set[str] = set()
        twice = sorted({n for n in names if n in seen or seen.add(n)})[:5]
        raise ValueError(f"'names' lists {', '.join(map(repr, twice))} more than once")
    unknown = [n for n in names if n not in position]
    if unknown:
        raise ValueError(f"'names' has {len(unknown)} name(s) that are not items of '{over}': "
                         f"{', '.join(map(repr, unknown[:5]))}{' ...' if len(unknown) > 5 else ''}")
    return list(names)


def _checked_pairs(pairs, n_names: int) -> np.ndarray:
    """The candidates' ``pairs`` as (P, 2) int64 indices in 0..n_names-1 with i != j (ValueError otherwise)."""
    pairs = np.asarray(pairs)
    if pairs.ndim != 2 or pairs.shape[1] != 2:
        raise ValueError(f"'pairs' has shape {pairs.shape}, expected (P, 2)")
    if pairs.size and pairs.dtype.kind not in "iu":
        raise ValueError(f"'pairs' must hold integer indices into 'names', got dtype {pairs.dtype}")
    pairs = pairs.astype(np.int64)
    bad = np.flatnonzero(((pairs < 0) | (pairs >= n_names)).any(axis=1))
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"pair {i} is {tuple(pairs[i].tolist())}: an index outside 0..{n_names - 1} "
                         f"(len(names) = {n_names}; {bad.size} such pair(s))")
    same = np.flatnonzero(pairs[:, 0] == pairs[:, 1])
    if same.size:
        i = int(same[0])
        raise ValueError(f"pair {i} is {tuple(pairs[i].tolist())}: an item paired with itself "
                         f"({same.size} such pair(s))")
    return pairs
