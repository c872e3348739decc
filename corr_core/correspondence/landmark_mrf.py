"""Landmark correspondence by a geodesic-consistency MRF, maximized with Leordeanu & Hebert (``corr_core.mrf``).

Nodes are the n template landmarks, labels the L test landmarks (n <= L). Assigning i -> a and j -> b is
rewarded when the (diameter-normalized) geodesic distances agree:

    W[i, j, a, b] = exp(-(dT[i, j] - dS[a, b])^2 / (2 sigma))          for i != j, a != b
    W[i, j, a, a] = 0                                                  for i != j

The zero for equal labels means two nodes that take the same label gain nothing from each other, so the
maximizer prefers one-to-one labelings; ``match_landmarks_mrf`` additionally guarantees a one-to-one answer
(see there). Geodesic distances are intrinsic, so a left/right intrinsic symmetry of the shape gives two
(near-)equally good labelings: the MRF resolves the *consistency* (whole limbs move together) but not the
symmetry (``corr_core.correspondence.orientation`` adds the chirality test that does).
"""
from __future__ import annotations

import numpy as np

from corr_core.correspondence.matching import hungarian_match
from corr_core.mrf import DensePairwise, energy, solve_lh


def consistency_pairwise(dT: np.ndarray, dS: np.ndarray, *, sigma: float = 0.05) -> np.ndarray:
    """Pairwise weights W: (n, n, L, L) from template distances dT (n,n) and test distances dS (L,L).

    W[i,j,a,b] = exp(-(dT[i,j] - dS[a,b])^2 / (2 sigma)); zero when i == j or a == b. Symmetric:
    W[i,j,a,b] == W[j,i,b,a] (dT, dS symmetric).
    """
    dT = np.asarray(dT, dtype=np.float64)
    dS = np.asarray(dS, dtype=np.float64)
    if dT.shape[0] != dT.shape[1] or dS.shape[0] != dS.shape[1]:
        raise ValueError("dT and dS must be square")
    if not (np.allclose(dT, dT.T) and np.allclose(dS, dS.T)):
        raise ValueError("dT and dS must be symmetric")
    if sigma <= 0:
        raise ValueError("sigma must be > 0")
    diff = dT[:, :, None, None] - dS[None, None, :, :]
    W = np.exp(-(diff**2) / (2.0 * sigma))
    n, L = len(dT), len(dS)
    W[np.arange(n), np.arange(n)] = 0.0
    W[:, :, np.arange(L), np.arange(L)] = 0.0
    return W


def descriptor_unary(cost: np.ndarray, *, weight: float = 1.0) -> np.ndarray:
    """Unary reward (n,L) from a descriptor distance matrix cost (n,L): weight * (1 - cost / max(cost)).

    Scaled to [0, weight] so that ``weight`` is comparable to one pairwise term (each lies in [0, 1]).
    """
    cost = np.asarray(cost, dtype=np.float64)
    top = float(cost.max())
    return weight * (1.0 - cost / top) if top > 0 else np.full(cost.shape, float(weight))


def improve_by_exchanges(pairwise: DensePairwise, unary: np.ndarray, labels: np.ndarray, *, max_rounds: int = 100,
                         extra=None) -> np.ndarray:
    """Local search over one-to-one labelings: accept the best label exchange between two nodes (or a move to
    an unused label) while it raises the energy (+ ``extra(labels)`` if given). labels: (n,) distinct ints."""
    labels = labels.copy()
    n, L = unary.shape

    def score(lab):
        return energy(pairwise, unary, lab) + (0.0 if extra is None else extra(lab))

    best = score(labels)
    for _ in range(max_rounds):
        candidates = []
        for i in range(n):
            for j in range(i + 1, n):
                cand = labels.copy()
                cand[i], cand[j] = labels[j], labels[i]
                candidates.append(cand)
            for a in np.setdiff1d(np.arange(L), labels):
                cand = labels.copy()
                cand[i] = a
                candidates.append(cand)
        energies = np.array([score(c) for c in candidates])
        k = int(np.argmax(energies))
        if energies[k] <= best + 1e-12:
            break
        best, labels = float(energies[k]), candidates[k]
    return labels


def match_landmarks_mrf(dT: np.ndarray, dS: np.ndarray, *, sigma: float = 0.05, unary: np.ndarray | None = None,
                        refine: bool = True, return_result: bool = False):
    """Match n template landmarks to L >= n test landmarks by the geodesic-consistency MRF.

    Args:
        dT: (n,n) template geodesic distances, dS: (L,L) test geodesic distances, both normalized by each
            surface's geodesic diameter (``corr_core.geometry.geodesic.landmark_geodesics``).
        sigma: consistency tolerance (units of squared normalized distance, see module docstring).
        unary: optional (n,L) reward added to the energy (e.g. ``descriptor_unary``); default none, i.e. a
            purely geodesic method.
    Returns:
        (n,) int distinct labels; with ``return_result`` also the ``LHResult`` of the solver.

    One-to-one guarantee: W[i,j,a,a] = 0 already makes shared labels unattractive. If the Leordeanu–Hebert
    labeling still repeats a label, it is replaced by the Hungarian assignment maximizing the relaxed
    solution, followed by an exchange local search that only accepts energy increases.
    """
    n, L = len(dT), len(dS)
    if n > L:
        raise ValueError(f"more template landmarks ({n}) than test landmarks ({L})")
    pairwise = DensePairwise(consistency_pairwise(dT, dS, sigma=sigma))
    U = np.zeros((n, L)) if unary is None else np.asarray(unary, dtype=np.float64)
    if U.shape != (n, L):
        raise ValueError(f"unary must have shape {(n, L)}, got {U.shape}")
    result = solve_lh(pairwise, U, compute_bound=False)
    labels = np.asarray(result.labels, dtype=np.int64)
    if len(np.unique(labels)) < n:
        labels = hungarian_match(-result.relaxed)
        refine = True
    if refine:
        labels = improve_by_exchanges(pairwise, U, labels)
    return (labels, result) if return_result else labels
