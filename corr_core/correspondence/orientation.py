"""Orientation (chirality): the symmetry breaker that intrinsic distances lack.

A left/right mirror map of a body is an isometry that REVERSES the surface orientation. For a landmark
triple (i, j, k), the sign of det[x_j - x_i, x_k - x_i, n_i] (n_i the outward vertex normal given by the
face winding) tells on which side of the tangent direction x_j - x_i the point k lies. Rigid motions keep
the sign, a mirror flips it, and near-isometric bending keeps it for triples that are close together on
the surface. Only the template decides which triples are used; the test mesh contributes its own positions
and normals at its own landmarks (no ground truth involved). ``match_landmarks_oriented`` combines it with the
geodesic MRF of ``corr_core.correspondence.landmark_mrf``.
"""
from __future__ import annotations

import numpy as np

from corr_core.correspondence.landmark_mrf import consistency_pairwise, improve_by_exchanges, match_landmarks_mrf
from corr_core.geometry.primitives import vertex_normals
from corr_core.mrf import DensePairwise

__all__ = ["landmark_chirality", "reliable_triples", "chirality_agreement", "match_landmarks_oriented"]


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


def reliable_triples(dT: np.ndarray, chiT: np.ndarray, radius: float | None = None, *, min_sine: float = 0.2,
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
                             *, sigma: float = 0.05, unary: np.ndarray | None = None, exclusion: float = 1.0,
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
    p1 = match_landmarks_mrf(dT, dS, sigma=sigma, unary=U)
    U2 = U.copy()
    U2[np.arange(n), p1] -= exclusion
    p2 = match_landmarks_mrf(dT, dS, sigma=sigma, unary=U2)
    best = p1 if chirality_agreement(chiT, chiS, p1, mask) >= chirality_agreement(chiT, chiS, p2, mask) else p2
    pairwise = DensePairwise(consistency_pairwise(dT, dS, sigma=sigma))
    extra = None
    if chirality_weight > 0 and mask.any():
        sign_t = np.sign(chiT[mask])

        def extra(lab):
            return chirality_weight * float(np.sum(sign_t == np.sign(chiS[np.ix_(lab, lab, lab)][mask])))

    # p2 was solved with the exclusion penalty; re-polish on the real objective (local exchanges cannot undo
    # a whole mirror flip, but they fix the plane points the exclusion pushed off their label)
    return improve_by_exchanges(pairwise, U, best, extra=extra)
