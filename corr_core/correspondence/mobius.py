"""Möbius voting for surface correspondence (Lipman & Funkhouser, SIGGRAPH 2009, sections 5-7).

Both surfaces are flattened to the complex plane (``corr_core.geometry.midedge``). A Möbius map ``m(z) = (a z + b) /
(c z + d)`` is fixed by three point pairs. For a source triplet ``(z1, z2, z3)`` and a target triplet
``(w1, w2, w3)`` we map each triplet to the *canonical frame*: the Möbius maps ``m_s``, ``m_t`` that send the
triplet to the cube roots of unity ``(1, e^{2 pi i/3}, e^{4 pi i/3})``. In that frame both triplets sit on the
unit circle, so distances are measured in units of the triplets' circumradius (= 1), symmetric in source
and target (the paper's design).

Deformation error and ``K``: after mapping the source samples by ``m_s`` and the target samples by ``m_t``,
pair the mutually closest points; a pair's deformation error is their Euclidean distance in the canonical
frame (``metric="plane"``) or, with ``metric="sphere"``, their chordal distance after inverse stereographic
projection to the unit sphere (bounded by 2; points near infinity are not over-weighted). A map's score is
the fraction of source samples that have a mutually closest partner within ``K`` (default 0.3, in canonical
frame units). Each map votes, with weight ``score``, for every pair of landmarks that are mutually closest
within ``K`` under it (the triplet's own three pairs always qualify, distance 0). Final correspondences:
the assignment (Hungarian) that maximizes the summed votes.
"""
from __future__ import annotations

from itertools import combinations, permutations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

ROOTS3 = np.exp(2j * np.pi * np.arange(3) / 3)


def _to_01inf(z: np.ndarray) -> np.ndarray:
    """(...,3) complex -> (...,2,2) matrix of the Möbius map sending z1, z2, z3 to 0, 1, inf."""
    z1, z2, z3 = z[..., 0], z[..., 1], z[..., 2]
    M = np.empty(z.shape[:-1] + (2, 2), dtype=complex)
    M[..., 0, 0] = z2 - z3
    M[..., 0, 1] = -z1 * (z2 - z3)
    M[..., 1, 0] = z2 - z1
    M[..., 1, 1] = -z3 * (z2 - z1)
    return M


def _adj(M: np.ndarray) -> np.ndarray:
    """Inverse up to scale (adjugate) of (...,2,2) matrices."""
    out = np.empty_like(M)
    out[..., 0, 0] = M[..., 1, 1]
    out[..., 1, 1] = M[..., 0, 0]
    out[..., 0, 1] = -M[..., 0, 1]
    out[..., 1, 0] = -M[..., 1, 0]
    return out


def _normalize(M: np.ndarray) -> np.ndarray:
    """Scale (...,2,2) Möbius matrices to determinant 1 (a projective representative)."""
    det = M[..., 0, 0] * M[..., 1, 1] - M[..., 0, 1] * M[..., 1, 0]
    return M / np.sqrt(det)[..., None, None]


def mobius_from_triplets(z: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The Möbius map f with f(z_k) = w_k, k = 0, 1, 2.

    Args:
        z, w: (..., 3) complex, each triplet of distinct finite points (batched over leading axes).
    Returns:
        (..., 4) complex coefficients ``(a, b, c, d)`` of ``f(x) = (a x + b) / (c x + d)``, ``ad - bc = 1``.
    """
    z = np.asarray(z, dtype=complex)
    w = np.asarray(w, dtype=complex)
    M = _normalize(_adj(_to_01inf(w)) @ _to_01inf(z))
    return M.reshape(M.shape[:-2] + (4,))


def mobius_to_canonical(z: np.ndarray) -> np.ndarray:
    """(...,3) complex triplets -> (...,4) coefficients of the map sending them to the cube roots of unity."""
    z = np.asarray(z, dtype=complex)
    return mobius_from_triplets(z, np.broadcast_to(ROOTS3, z.shape))


def compose_mobius(outer: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """Coefficients (...,4) of ``outer o inner``."""
    M = np.asarray(outer).reshape(np.shape(outer)[:-1] + (2, 2)) @ np.asarray(inner).reshape(
        np.shape(inner)[:-1] + (2, 2))
    return _normalize(M).reshape(M.shape[:-2] + (4,))


def invert_mobius(coeffs: np.ndarray) -> np.ndarray:
    """Coefficients (...,4) of the inverse map."""
    c = np.asarray(coeffs)
    return _normalize(_adj(c.reshape(c.shape[:-1] + (2, 2)))).reshape(c.shape)


def apply_mobius(coeffs: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Evaluate ``(a z + b) / (c z + d)``.

    Args:
        coeffs: (..., 4) complex; leading axes broadcast against a new trailing axis of ``z``.
        z: (n,) complex; ``inf`` entries are allowed (the point at infinity).
    Returns:
        (..., n) complex. The pole ``z = -d/c`` maps to ``inf + 0j``; ``z = inf`` maps to ``a / c``
        (``inf`` when ``c == 0``).
    """
    c = np.asarray(coeffs, dtype=complex)[..., None, :]
    z = np.asarray(z, dtype=complex)
    a, b, cc, d = c[..., 0], c[..., 1], c[..., 2], c[..., 3]
    at_inf = np.isinf(z)
    zf = np.where(at_inf, 0, z)
    num = a * zf + b
    den = cc * zf + d
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(den == 0, complex(np.inf, 0), num / np.where(den == 0, 1, den))
        lim = np.where(cc == 0, complex(np.inf, 0), a / np.where(cc == 0, 1, cc))
    return np.where(at_inf, lim, out)


def to_sphere(z: np.ndarray) -> np.ndarray:
    """Inverse stereographic projection of (...) complex onto the unit sphere -> (...,3); inf -> north pole."""
    z = np.asarray(z, dtype=complex)
    fin = np.isfinite(z)
    zf = np.where(fin, z, 0)
    r2 = np.abs(zf) ** 2
    P = np.stack([2 * zf.real, 2 * zf.imag, r2 - 1], axis=-1) / (1 + r2)[..., None]
    P[~fin] = [0.0, 0.0, 1.0]
    return P


def _xy(z: np.ndarray) -> np.ndarray:
    """(n,) complex -> (n,2) float; infinite points are parked far away (1e150) so KD-trees stay valid."""
    z = np.where(np.isfinite(z), z, 1e150)
    return np.c_[z.real, z.imag]


def mutually_closest_pairs(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j) with B[j] the nearest point of B to A[i] and A[i] the nearest of A to B[j].

    Args:
        A: (p,) complex, B: (q,) complex.
    Returns:
        pairs: (r, 2) int (sorted by i), dist: (r,) float |A[i] - B[j]|.
    """
    A = np.asarray(A, dtype=complex)
    B = np.asarray(B, dtype=complex)
    D = np.abs(A[:, None] - B[None, :])
    D = np.where(np.isnan(D), np.inf, D)
    j = np.argmin(D, axis=1)
    i_back = np.argmin(D, axis=0)
    i = np.flatnonzero(i_back[j] == np.arange(len(A)))
    pairs = np.stack([i, j[i]], axis=1)
    return pairs, D[i, j[i]]


def _batch_mutual(D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """D: (T, p, q) distances -> (mask (T,p) of source points with a mutual partner, partner (T,p))."""
    j = np.argmin(D, axis=2)
    i_back = np.argmin(D, axis=1)
    mutual = np.take_along_axis(i_back, j, axis=1) == np.arange(D.shape[1])[None, :]
    return mutual, j


def mobius_derivative_abs(coeffs: np.ndarray, z: np.ndarray) -> np.ndarray:
    """|f'(z)| = |ad - bc| / |c z + d|^2 for coeffs (...,4) and z (n,) -> (..., n)."""
    c = np.asarray(coeffs, dtype=complex)[..., None, :]
    det = c[..., 0] * c[..., 3] - c[..., 1] * c[..., 2]
    with np.errstate(divide="ignore"):
        return np.abs(det) / np.abs(c[..., 2] * np.asarray(z) + c[..., 3]) ** 2


def _distances(A: np.ndarray, B: np.ndarray, metric: str, LA: np.ndarray | None = None,
               LB: np.ndarray | None = None) -> np.ndarray:
    """(T,p) and (T,q) complex -> (T,p,q) distances in the canonical frame.

    ``surface``: planar distance divided by the local planar scale sqrt(LA LB) (LA, LB: (T,p), (T,q) planar
    length per unit length), i.e. an estimate of the distance on the surface, in the unit that ``lam`` uses.
    """
    if metric == "plane":
        D = np.abs(A[:, :, None] - B[:, None, :])
    elif metric == "sphere":
        D = np.linalg.norm(to_sphere(A)[:, :, None, :] - to_sphere(B)[:, None, :, :], axis=-1)
    elif metric == "surface":
        if LA is None or LB is None:
            raise ValueError("metric 'surface' needs the local scales (lam_*) of both point sets")
        D = np.abs(A[:, :, None] - B[:, None, :]) / np.sqrt(LA[:, :, None] * LB[:, None, :])
    else:
        raise ValueError(f"unknown metric {metric!r} (use 'plane', 'sphere' or 'surface')")
    return np.where(np.isnan(D), np.inf, D)


def _map_points(m: np.ndarray, Z: np.ndarray, lam: np.ndarray | None):
    """Map points by (T,4) maps -> positions (T,n) and, if lam (n,) is given, local scales (T,n)."""
    A = apply_mobius(m, Z)
    L = None if lam is None else np.asarray(lam)[None, :] * mobius_derivative_abs(m, Z)
    return A, L


def triplet_pairs(n_source: int, n_target: int) -> tuple[np.ndarray, np.ndarray]:
    """All (3-subset of source, ordered 3-tuple of target) index pairs -> src (T,3), tgt (T,3) int.

    Only target orderings with the same orientation class are needed in principle, but all 6 orders are tried
    (orientation-reversing orders simply score badly because Möbius maps preserve orientation).
    """
    S = np.array(list(combinations(range(n_source), 3)), dtype=np.int64)
    T = np.array(list(permutations(range(n_target), 3)), dtype=np.int64)
    src = np.repeat(S, len(T), axis=0)
    tgt = np.tile(T, (len(S), 1))
    return src, tgt


# Triplet maps scored per block: a block holds chunk x p x q complex distances, and small blocks stay in the CPU
# caches through the five passes over them. `python bench/mobius_chunk.py` (random maps, 600 x 300 x 300, quiet
# machine, 2026-12-02): chunk 256 0.579 s, 16 0.413 s, 8 0.320 s, 4 0.265 s, 2 0.263 s, 1 0.276 s; the same scores,
# bit for bit, at every size.
SCORE_CHUNK = 4


def score_maps(ms: np.ndarray, mt: np.ndarray, Zs_samples: np.ndarray, Zt_samples: np.ndarray, *, K: float = 0.3,
               metric: str = "plane", lam_s: np.ndarray | None = None, lam_t: np.ndarray | None = None,
               K_scale: float | None = None, chunk: int = SCORE_CHUNK) -> np.ndarray:
    """Score Möbius map pairs by the fraction of source samples mutually closest to a target sample within K.

    Args:
        ms, mt: (T, 4) complex canonical-frame maps of source and target.
        Zs_samples: (p,) complex, Zt_samples: (q,) complex flattened samples.
        metric: "plane", "sphere" or "surface" (needs lam_s, lam_t: (p,), (q,) planar length per unit of K
            at each sample, e.g. ``midedge_conformal_factor`` times the unit length on the surface).
        K_scale: with metric "surface", a pair also needs ``|log(local scale ratio)| < K_scale``: the two
            points must be stretched alike by their flattenings + frames (an isometry keeps them equal).
    Returns:
        (T,) float in [0, 1], the fraction (over min(p, q) samples).
    """
    out = np.empty(len(ms))
    denom = min(len(Zs_samples), len(Zt_samples))
    for s in range(0, len(ms), chunk):          # chunks bound memory (T*p*q distances) and stay in cache
        A, LA = _map_points(ms[s:s + chunk], Zs_samples, lam_s)
        B, LB = _map_points(mt[s:s + chunk], Zt_samples, lam_t)
        D = _distances(A, B, metric, LA, LB)
        mutual, j = _batch_mutual(D)
        d = np.take_along_axis(D, j[:, :, None], axis=2)[:, :, 0]
        good = mutual & (d < K)
        if K_scale is not None and LA is not None:
            good &= np.abs(np.log(LA / np.take_along_axis(LB, j, axis=1))) < K_scale
        out[s:s + chunk] = good.sum(axis=1) / denom
    return out


def mobius_vote_landmarks(Zs_samples: np.ndarray, Zt_samples: np.ndarray, Zs_landmarks: np.ndarray,
                          Zt_landmarks: np.ndarray, *, K: float = 0.3, metric: str = "plane",
                          n_best: int = 20, lam_samples: tuple | None = None,
                          lam_landmarks: tuple | None = None, power: float = 1.0,
                          K_scale: float | None = None) -> dict:
    """Möbius voting over all landmark triplet pairs.

    Recommended on SCAPE-like meshes (measured, docs/mobius_notes.md): 300 farthest-point samples,
    ``metric="surface"`` with ``lam = midedge_conformal_factor * sqrt(area / n_samples)``, ``K=0.5``,
    ``K_scale=0.3``, ``power=4``; the plain defaults (``metric="plane"``, K=0.3) follow the paper's frame but
    do not separate good from bad maps there.

    Every 3-subset of source landmarks is paired with every ordered triple of target landmarks; each pair
    defines canonical-frame maps ``ms``, ``mt`` (see module docstring) which are scored on the samples and
    vote, weighted by the score, for the landmark pairs mutually closest within ``K``.

    Args:
        Zs_samples: (p,) complex, flattened source samples (e.g. 80-100 farthest-point samples).
        Zt_samples: (q,) complex, flattened target samples.
        Zs_landmarks: (k,) complex, Zt_landmarks: (k2,) complex, flattened landmarks (k, k2 >= 3).
        K: distance threshold in canonical-frame units.
        metric: "plane", "sphere" or "surface" (see module docstring).
        n_best: how many best maps to return.
        lam_samples: (lam_s (p,), lam_t (q,)) local scales for metric "surface" (see ``score_maps``).
        lam_landmarks: (lam_s (k,), lam_t (k2,)) local scales at the landmarks, for metric "surface".
        power: a map votes with weight ``score ** power`` (larger: only the best maps matter).
        K_scale: see ``score_maps`` (metric "surface" only).
    Returns:
        dict with ``pred`` (k,) int (target landmark for each source landmark, -1 if k > k2 and unmatched),
        ``votes`` (k, k2) float, ``best_maps`` list of dicts (score, ms, mt, src triplet, tgt triplet,
        coeffs = mt^-1 o ms mapping the source plane to the target plane), best first, and ``scores`` (T,).
    """
    Zs_landmarks = np.asarray(Zs_landmarks, dtype=complex)
    Zt_landmarks = np.asarray(Zt_landmarks, dtype=complex)
    src, tgt = triplet_pairs(len(Zs_landmarks), len(Zt_landmarks))
    ms = mobius_to_canonical(Zs_landmarks[src])
    mt = mobius_to_canonical(Zt_landmarks[tgt])
    ls, lt = lam_samples if lam_samples is not None else (None, None)
    scores = score_maps(ms, mt, Zs_samples, Zt_samples, K=K, metric=metric, lam_s=ls, lam_t=lt, K_scale=K_scale)

    ls, lt = lam_landmarks if lam_landmarks is not None else (None, None)
    A, LA = _map_points(ms, Zs_landmarks, ls)
    B, LB = _map_points(mt, Zt_landmarks, lt)
    D = _distances(A, B, metric, LA, LB)
    mutual, j = _batch_mutual(D)
    d = np.take_along_axis(D, j[:, :, None], axis=2)[:, :, 0]
    ok = mutual & (d < K)
    t_idx, i_idx = np.nonzero(ok)
    votes = np.zeros((len(Zs_landmarks), len(Zt_landmarks)))
    np.add.at(votes, (i_idx, j[t_idx, i_idx]), scores[t_idx] ** power)

    rows, cols = linear_sum_assignment(-votes)
    pred = np.full(len(Zs_landmarks), -1, dtype=np.int64)
    pred[rows] = cols
    def as_dict(t):
        return {"score": float(scores[t]), "ms": ms[t], "mt": mt[t], "src": src[t], "tgt": tgt[t],
                "coeffs": compose_mobius(invert_mobius(mt[t]), ms[t])}

    order = np.argsort(-scores, kind="stable")
    agrees = np.all(pred[src] == tgt, axis=1)
    return {"pred": pred, "votes": votes, "scores": scores,
            "best_maps": [as_dict(t) for t in order[:n_best]],
            "consensus_maps": [as_dict(t) for t in order[agrees[order]]]}


def extend_landmarks(best_maps: list, Zs_all_landmarks: np.ndarray, Zt_candidates: np.ndarray, *, top: int = 10,
                     assign: bool = True, metric: str = "plane") -> np.ndarray:
    """Carry all source landmarks to the target with the best maps.

    Each of the ``top`` best maps sends the source landmarks and the target candidates to the canonical
    frame and votes (weight = map score) for the candidate nearest to each source landmark.

    Args:
        best_maps: as returned by ``mobius_vote_landmarks`` (needs ``ms``, ``mt``, ``score``).
        Zs_all_landmarks: (k,) complex, flattened source landmarks (e.g. the 20 template landmarks).
        Zt_candidates: (q,) complex, flattened target candidates: the target's landmarks (then ``assign``
            makes the result one-to-one with the Hungarian method) or all target mid-edge points.
        top: number of best maps that vote.
        assign: one-to-one assignment on the vote matrix (needs q >= k); otherwise per-landmark argmax.
    Returns:
        (k,) int candidate index for each source landmark.
    """
    maps = best_maps[:top]
    ms = np.stack([m["ms"] for m in maps])
    mt = np.stack([m["mt"] for m in maps])
    w = np.array([m["score"] for m in maps])
    A = apply_mobius(ms, Zs_all_landmarks)                  # (top, k)
    B = apply_mobius(mt, Zt_candidates)                     # (top, q)
    if metric == "sphere":
        nn = np.stack([cKDTree(to_sphere(b)).query(to_sphere(a))[1] for a, b in zip(A, B)])
    else:
        nn = np.stack([cKDTree(_xy(b)).query(_xy(a))[1] for a, b in zip(A, B)])   # (top, k), one query per map
    k = len(Zs_all_landmarks)
    if assign and len(Zt_candidates) <= 4096:
        votes = np.zeros((k, len(Zt_candidates)))
        np.add.at(votes, (np.tile(np.arange(k), len(maps)), nn.ravel()), np.repeat(w, k))
        rows, cols = linear_sum_assignment(-votes)
        out = np.full(k, -1, dtype=np.int64)
        out[rows] = cols
        return out
    out = np.empty(k, dtype=np.int64)
    for i in range(k):                                       # k landmarks, small
        vals, inv = np.unique(nn[:, i], return_inverse=True)
        out[i] = vals[np.argmax(np.bincount(inv, weights=w))]
    return out


def dense_map(best_map: dict, Zs_all: np.ndarray, Zt_all: np.ndarray, metric: str = "plane") -> np.ndarray:
    """Nearest-neighbour dense map under one Möbius map.

    Args:
        best_map: a dict with ``ms``, ``mt`` (canonical-frame maps), e.g. ``best_maps[0]``.
        Zs_all: (n_s,) complex, all flattened source mid-edge points. Zt_all: (n_t,) complex, target ones.
    Returns:
        (n_s,) int, index of the nearest target mid-edge point (in the canonical frame) for each source one.
    """
    A = apply_mobius(best_map["ms"], Zs_all)
    B = apply_mobius(best_map["mt"], Zt_all)
    if metric == "sphere":
        return cKDTree(to_sphere(B)).query(to_sphere(A))[1].astype(np.int64)
    return cKDTree(_xy(B)).query(_xy(A))[1].astype(np.int64)


def fit_mobius(z: np.ndarray, w: np.ndarray, refine: bool = True) -> np.ndarray:
    """Least-squares Möbius map with f(z_i) ~ w_i (orientation-preserving; pass conj(z) for anti-Möbius).

    Algebraic fit (smallest singular vector of ``a z + b - c z w - d w = 0``, rows normalized) followed, with
    ``refine``, by Levenberg-Marquardt on the geometric residual ``|f(z_i) - w_i|``.

    Args:
        z, w: (n,) complex, n >= 3, finite.
    Returns:
        (4,) complex coefficients (a, b, c, d), ``ad - bc = 1``.
    """
    from scipy.optimize import least_squares

    z = np.asarray(z, dtype=complex)
    w = np.asarray(w, dtype=complex)
    A = np.stack([z, np.ones_like(z), -z * w, -w], axis=1)
    A /= np.linalg.norm(A, axis=1, keepdims=True)
    coeffs = np.conj(np.linalg.svd(A, full_matrices=False)[2][-1])
    if refine:
        def residual(x):
            r = apply_mobius(x[:4] + 1j * x[4:], z) - w
            return np.r_[r.real, r.imag]
        x = least_squares(residual, np.r_[coeffs.real, coeffs.imag], method="lm").x
        coeffs = x[:4] + 1j * x[4:]
    return _normalize(coeffs.reshape(2, 2)).ravel()
