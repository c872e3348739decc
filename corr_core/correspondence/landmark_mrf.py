"""Landmark correspondence by a geodesic-consistency MRF, maximized with Leordeanu & Hebert (``corr_core.mrf``).

Nodes are the n template landmarks, labels the L test landmarks (n <= L). Assigning i -> a and j -> b is
rewarded when the (diameter-normalized) geodesic distances agree:

    W[i, j, a, b] = exp(-(dT[i, j] - dS[a, b])^2 / (2 sigma))          for i != j, a != b
    W[i, j, a, a] = 0                                                  for i != j

The zero for equal labels means two nodes that take the same label gain nothing from each other, so the
maximizer prefers one-to-one labelings; ``match_landmarks_mrf`` additionally guarantees a one-to-one answer
(see there). Geodesic distances are intrinsic, so a left/right intrinsic symmetry of the shape gives two
(near-)equally good labelings: the MRF resolves the *consistency* (whole limbs move together) but not the
symmetry.
"""
from __future__ import annotations

import numpy as np

from corr_core.correspondence.matching import hungarian_match
from corr_core.mrf import DensePairwise, energy, solve_lh


def consistency_pairwise(dT: np.ndarray, dS: np.ndarray, sigma: float = 0.05) -> np.ndarray:
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


def descriptor_unary(cost: np.ndarray, weight: float = 1.0) -> np.ndarray:
    """Unary reward (n,L) from a descriptor distance matrix cost (n,L): weight * (1 - cost / max(cost)).

    Scaled to [0, weight] so that ``weight`` is comparable to one pairwise term (each lies in [0, 1]).
    """
    cost = np.asarray(cost, dtype=np.float64)
    top = float(cost.max())
    return weight * (1.0 - cost / top) if top > 0 else np.full(cost.shape, float(weight))


def _swap_improve(pairwise: DensePairwise, unary: np.ndarray, labels: np.ndarray, max_rounds: int = 100,
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


def match_landmarks_mrf(dT: np.ndarray, dS: np.ndarray, sigma: float = 0.05, unary: np.ndarray | None = None,
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
    pairwise = DensePairwise(consistency_pairwise(dT, dS, sigma))
    U = np.zeros((n, L)) if unary is None else np.asarray(unary, dtype=np.float64)
    if U.shape != (n, L):
        raise ValueError(f"unary must have shape {(n, L)}, got {U.shape}")
    result = solve_lh(pairwise, U, compute_bound=False)
    labels = np.asarray(result.labels, dtype=np.int64)
    if len(np.unique(labels)) < n:
        labels = hungarian_match(-result.relaxed)
        refine = True
    if refine:
        labels = _swap_improve(pairwise, U, labels)
    return (labels, result) if return_result else labels


# ---------------------------------------------------------------------------------------------------------
# Orientation (chirality): the symmetry breaker that intrinsic distances lack.
#
# A left/right mirror map of a body is an isometry that REVERSES the surface orientation. For a landmark
# triple (i, j, k), the sign of det[x_j - x_i, x_k - x_i, n_i] (n_i the outward vertex normal given by the
# face winding) tells on which side of the tangent direction x_j - x_i the point k lies. Rigid motions keep
# the sign, a mirror flips it, and near-isometric bending keeps it for triples that are close together on
# the surface. Only the template decides which triples are used; the test mesh contributes its own positions
# and normals at its own landmarks (no ground truth involved).


def vertex_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(n,3) unit area-weighted vertex normals; direction from the face winding (counter-clockwise = outward)."""
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    N = np.zeros_like(V, dtype=np.float64)
    for c in range(3):
        np.add.at(N, F[:, c], fn)
    return N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-300)


def landmark_chirality(V: np.ndarray, F: np.ndarray, vids) -> np.ndarray:
    """Chirality of landmark triples: C[i,j,k] = det[x_j - x_i, x_k - x_i, n_i] / (|x_j - x_i| |x_k - x_i|).

    Args: V: (n,3); F: (m,3) consistently oriented; vids: (k,) int landmark vertex ids.
    Returns: (k,k,k) float in [-1,1] (a signed sine), antisymmetric in (j,k); invariant to rigid motions and
    scale, negated by a mirror image.
    """
    vids = np.asarray(vids, dtype=np.int64)
    X = np.asarray(V, dtype=np.float64)[vids]
    N = vertex_normals(np.asarray(V, dtype=np.float64), np.asarray(F))[vids]
    A = X[None, :, :] - X[:, None, :]  # A[i, j] = x_j - x_i
    det = np.einsum("ijkc,ic->ijk", np.cross(A[:, :, None, :], A[:, None, :, :]), N)
    length = np.linalg.norm(A, axis=2)
    return det / np.maximum(length[:, :, None] * length[:, None, :], 1e-300)


def reliable_triples(dT: np.ndarray, chiT: np.ndarray, radius: float | None = None, min_sine: float = 0.2,
                     min_count: int | None = None) -> np.ndarray:
    """Template triples whose chirality is trusted: all three pairwise normalized geodesic distances < radius
    (local, so bending does not flip it) and |chirality| >= min_sine (not nearly collinear).

    radius=None picks the smallest of 0.25, 0.5, 1.0 that yields at least ``min_count`` (default 3k) triples.
    Returns (k,k,k) bool.
    """
    k = len(dT)
    min_count = 3 * k if min_count is None else min_count
    radii = [radius] if radius is not None else [0.25, 0.5, 1.0 + 1e-9]
    for r in radii:
        close = dT < r
        mask = close[:, :, None] & close[:, None, :] & close[None, :, :] & (np.abs(chiT) >= min_sine)
        if mask.sum() >= min_count:
            break
    return mask


def chirality_agreement(chiT: np.ndarray, chiS: np.ndarray, labels: np.ndarray, mask: np.ndarray) -> float:
    """Fraction of trusted template triples (mask) whose chirality sign is kept by the labeling.

    chiT: (n,n,n) template; chiS: (L,L,L) test; labels: (n,) int; mask: (n,n,n) bool. Returns float in [0,1]
    (nan if the mask is empty).
    """
    if not mask.any():
        return float("nan")
    mapped = chiS[np.ix_(labels, labels, labels)]
    return float(np.mean(np.sign(chiT[mask]) == np.sign(mapped[mask])))


def match_landmarks_oriented(dT: np.ndarray, dS: np.ndarray, chiT: np.ndarray, chiS: np.ndarray,
                             sigma: float = 0.05, unary: np.ndarray | None = None, exclusion: float = 1.0,
                             chirality_weight: float = 0.0, radius: float | None = None) -> np.ndarray:
    """Geodesic MRF plus orientation: resolves the left/right symmetry that ``match_landmarks_mrf`` cannot.

    1. p1 = ``match_landmarks_mrf`` (best geodesically consistent labeling found).
    2. p2 = the same MRF with the reward of every (i, p1[i]) lowered by ``exclusion``: the next consistent
       labeling, which for a bilaterally symmetric shape is the mirror image of p1 (points on the symmetry
       plane keep their label because their pairwise gains outweigh the exclusion).
    3. keep the candidate whose chirality agrees with the template on more trusted triples
       (``reliable_triples``), then refine it by exchanges maximizing
       energy + chirality_weight * (number of agreeing trusted triples).

    Args: dT (n,n), dS (L,L) normalized geodesics; chiT (n,n,n), chiS (L,L,L) from ``landmark_chirality``;
    sigma, unary as in ``match_landmarks_mrf``; exclusion: penalty that forces the second candidate;
    chirality_weight: default 0 (chirality only chooses between the two candidates): on SCAPE a weight of 1
    helped little with 20 landmarks and hurt with 5 far-apart ones, whose triples bend with the pose;
    radius: see ``reliable_triples``. Returns (n,) int distinct labels.
    """
    n, L = len(dT), len(dS)
    U = np.zeros((n, L)) if unary is None else np.asarray(unary, dtype=np.float64)
    mask = reliable_triples(dT, chiT, radius=radius)
    p1 = match_landmarks_mrf(dT, dS, sigma, U)
    U2 = U.copy()
    U2[np.arange(n), p1] -= exclusion
    p2 = match_landmarks_mrf(dT, dS, sigma, U2)
    best = p1 if chirality_agreement(chiT, chiS, p1, mask) >= chirality_agreement(chiT, chiS, p2, mask) else p2
    pairwise = DensePairwise(consistency_pairwise(dT, dS, sigma))
    extra = None
    if chirality_weight > 0 and mask.any():
        sign_t = np.sign(chiT[mask])

        def extra(lab):
            return chirality_weight * float(np.sum(sign_t == np.sign(chiS[np.ix_(lab, lab, lab)][mask])))

    # p2 was solved with the exclusion penalty; re-polish on the real objective (local exchanges cannot undo
    # a whole mirror flip, but they fix the plane points the exclusion pushed off their label)
    return _swap_improve(pairwise, U, best, extra=extra)
