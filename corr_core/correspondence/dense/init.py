"""Initial dense maps: from a few points given on both meshes, or fully automatic.

From points (``map_from_points``): the geodesic distance to each given point, its localized versions
exp(-(d / s)^2) and the pairwise *chirality functions* (``fmaps.chirality_functions``: the signed sine between the
directions to two points; it flips sign on a mirror image, so belly/back and left/right are told apart) are
corresponding functions on both meshes. A functional map fitted to them (descriptors + Laplacian
commutativity, ``fmaps.fit_functional_map``; its orientation term is available but off by default: with these
point-based descriptors it shrank the map and raised the error on SCAPE) is refined by ZoomOut.

Automatic (``map_automatic``): feature points are detected on each mesh independently (``extremities``: local
maxima of the average geodesic distance, i.e. hands, feet and head of a body). Assignments between the two sets
are ranked by how well they preserve the geodesic distances between the points, after taking out a global scale
(``ranked_assignments(scale_invariant=True)``: a bent or thinner body has shorter geodesics at the same area),
and each of the best ``keep`` is turned into a coarse probe map by ``map_from_points`` (target distance fields
rescaled likewise; ZoomOut to ``k_probe`` on ``n_probe`` samples). Distances cannot tell a map from its mirror,
nor, on a body, the true map from the 180-degree turn (left<->right *and* front<->back) or from a twist (only the
hands or only the feet swapped), so the probes are scored afterwards: ``chirality_agreement`` (the template's
chirality functions vs the target's at the probe images: < 0 for a mirror map, a fraction for a twist) keeps the
candidates above 2/3 of the best one's, and among those the map whose wave kernel signatures agree best wins
(``wks_disagreement``, on the template's energy bands, scale-normalized: the front of a body differs from its
back in the face, chest and feet). The winner goes on with ZoomOut to ``k_end`` (``automatic_hypotheses``: the
N best ranked do, and ``refine.refine_best`` decides after refinement: for bodies whose front and back look alike, where
the WKS difference between the true map and the turn is a few percent either way). ``orientation_agreement``
(local linear fits) and ``hks_disagreement`` are reported in ``return_info`` but not used: on coarse probes the
first is noise, and the second (low-pass) misses the front/back differences (measured on the course poses).
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations

import numpy as np
from scipy.spatial import cKDTree

from corr_core.correspondence.dense import fmaps, zoomout
from corr_core.correspondence.dense.basis import MeshBasis, in_size_of
from corr_core.geometry.primitives import vertex_adjacency

LOCAL_SCALES = (0.1, 0.2, 0.4)       # widths of exp(-(d/s)^2), units sqrt(area)
# Weight of the chirality columns of ``point_features`` (the automatic probes' and ``map_from_points``' fits). Chosen
# by `python bench/dense_constants.py --seeds 10-13` (generated other bodies, 20 targets; docs/dense.md "Tuned
# constants"): 0 (nothing tells a map from its mirror image) flips 7 of 20 automatic maps; 0.15 / 0.3 / 0.5 give
# mean errors 0.01266 / 0.01301 / 0.01325 on the right maps, 0.01328 / 0.01355 / 0.01338 from the sparse points: a
# plateau, 0.3 stays.
CHIRALITY_WEIGHT = 0.3
ZOOMOUT_SAMPLES = 2000           # template samples (and target samples or vertices) ZoomOut iterates on
# Growth of the basis per ZoomOut iteration of the starting maps (``map_from_points``; the final ZoomOut of every
# automatic hypothesis; the probes keep 5). Chosen by `python bench/zoomout_steps.py --seeds 10-13 --steps 2,4,6`
# (generated other bodies, 20 targets, k 30 -> 60, from the 5 points: mean errors 0.01304 / 0.01254 / 0.01262,
# step 4 lower on 12 of 20) and the same with `--course-settings` (k 40 -> 100; from the points 0.01356 / 0.01358 /
# 0.01389, automatic 0.01515 / 0.01482 / 0.01450; no flip at any step); the automatic maps again with `--seeds 14-17
# --course-settings --steps 2,4 --modes auto`: 0.01588 / 0.01508, lower on 16 of 20. 4 is as accurate as 2 or better
# at 21 % less CPU time for the sparse map, 17-18 % for the automatic one; 6 is worse from the points (docs/dense.md
# "ZoomOut step").
ZOOMOUT_STEP = 4
# Candidates kept: chirality agreement above this fraction of the best's. `python bench/chirality_pool.py --seeds
# 10-14 --poses 4` (generated other bodies): right maps 0.773-1.000 of the best's, turns 0.839-1.000, twists
# 0.323-0.889, so 2/3 keeps every right map (margin 0.106) and drops only the clearest twists (docs/dense.md).
CHIRALITY_POOL = 2 / 3
# How many ranked initial maps the automatic mode refines (``hypotheses_to_refine``): always the best two (the
# second is the reference of the map's confidence, ``refine.BestMap``), and any further candidate of the chirality
# pool whose WKS disagreement is within HYPOTHESIS_WKS_RATIO of the best's, up to MAX_HYPOTHESES. On generated
# bodies (`python bench/dense_hypotheses.py --seeds 0-9 --candidates 2`, docs/dense.md "Confidence") the
# runner-up's WKS was within 1.09x of the best's (a judged ratio just above that; twists, a limb pair swapped,
# are outside the chirality pool).
MIN_HYPOTHESES = 2
MAX_HYPOTHESES = 3
HYPOTHESIS_WKS_RATIO = 1.10


def point_features(basis: MeshBasis, points: np.ndarray, *, chirality_weight: float = CHIRALITY_WEIGHT,
                   scales=LOCAL_SCALES, distances: np.ndarray | None = None) -> np.ndarray:
    """Vertex functions that follow from a few labelled points.

    Args: basis: the mesh; points: (L,) int vertex ids (L >= 2; the order is the labelling);
        distances: optional (L, n) ``basis.distances(points)`` (reused when given).
    Returns: (n, L (1 + len(scales)) + L (L - 1) / 2) float: distances / sqrt(area), exp(-(d/s)^2) per scale,
        chirality functions times ``chirality_weight``.
    """
    points = np.asarray(points, dtype=np.int64)
    if points.ndim != 1 or len(points) < 2:
        raise ValueError(f"need at least 2 points, got {points.shape}")
    if points.min() < 0 or points.max() >= basis.n:
        raise ValueError(f"point ids must be in 0..{basis.n - 1}, got {points.min()}..{points.max()}")
    d = (basis.point_distances(points) if distances is None else np.asarray(distances)).T
    local = [np.exp(-(d / s) ** 2) for s in scales]
    return np.concatenate([d] + local + [chirality_weight * fmaps.chirality_functions(basis, d)], axis=1)


# ``kept_point_features`` keeps this many feature sets per basis: the automatic mode asks a template for one per
# assigned subset of its extremities (one when it has no more than the target; at most C(7, 3) = 35), the sparse
# mode for one per landmark set.
MAX_KEPT_FEATURE_SETS = 64


def kept_point_features(basis: MeshBasis, points: np.ndarray, *,
                        chirality_weight: float = CHIRALITY_WEIGHT) -> np.ndarray:
    """``point_features(basis, points)`` (default scales, distances from ``basis.point_distances``), computed once
    per basis, points and weight, then kept read-only (up to ``MAX_KEPT_FEATURE_SETS``): a template's features are
    the same for every target. Returns (n, ...) float as ``point_features``."""
    kept = basis.cached("point_features", dict)
    key = (tuple(np.asarray(points, dtype=np.int64).tolist()), float(chirality_weight))
    if key in kept:
        return kept[key]
    features = point_features(basis, np.asarray(points, dtype=np.int64), chirality_weight=chirality_weight)
    if len(kept) < MAX_KEPT_FEATURE_SETS:
        features.setflags(write=False)
        kept[key] = features
    return features


def fmap_from_points(source: MeshBasis, target: MeshBasis, points_source: np.ndarray, points_target: np.ndarray, *,
                     k: int = 40, w_lap: float = 0.1, w_orient: float = 0.0, features=None) -> np.ndarray:
    """Functional map (k x k, template x target) fitted to the point features of corresponding points.

    Args: points_source, points_target: (L,) int corresponding vertex ids; features: optional precomputed
        (F_source, F_target) from ``point_features``. Returns C: (k, k).
    """
    if len(points_source) != len(points_target):
        raise ValueError(f"{len(points_source)} template points but {len(points_target)} target points")
    target = in_size_of(target, source)                 # at the template's size (basis.in_size_of)
    FS, FT = features if features is not None else (kept_point_features(source, points_source),
                                                    point_features(target, points_target))
    k = int(min(k, source.evecs.shape[1], target.evecs.shape[1]))
    A_S, A_T = fmaps.project(source, FS, k), fmaps.project(target, FT, k)
    Om_S = Om_T = None
    if w_orient > 0:
        Om_S, Om_T = fmaps.orientation_operators(source, FS, k), fmaps.orientation_operators(target, FT, k)
    return fmaps.fit_functional_map(A_S, A_T, source.evals, target.evals, Om_S, Om_T, w_lap=w_lap, w_orient=w_orient)


def map_from_points(source: MeshBasis, target: MeshBasis, points_source, points_target, *, k_init: int = 40,
                    k_end: int = 100, step: int = ZOOMOUT_STEP, features=None,
                    n_zoomout: int | None = ZOOMOUT_SAMPLES,
                    all_target_vertices: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Functional map from corresponding points, refined by ZoomOut on the samples.

    ZoomOut (adjoint point maps, ``zoomout.zoomout``) iterates on the first ``n_zoomout`` template samples (None:
    all), matched to every target vertex (``all_target_vertices``) or to the target's first ``n_zoomout`` samples;
    the returned point map is computed at all template samples with the final functional map. ``points_source`` /
    ``points_target`` are original vertex ids (as in landmark files; ``MeshBasis.to_local`` converts them).
    Returns: C: (k_end, k_end) functional map, p2p_samples: (len(source.samples),) int target vertex of each
    template sample.
    """
    target = in_size_of(target, source)                 # at the template's size (basis.in_size_of)
    points_source = source.to_local(points_source, what="template point")
    points_target = target.to_local(points_target, what="target point")
    C = fmap_from_points(source, target, points_source, points_target, k=k_init, features=features)
    return _zoomout_and_match(source, target, C, k_end=k_end, step=step, n_zoomout=n_zoomout,
                              all_target_vertices=all_target_vertices)


def _zoomout_and_match(source: MeshBasis, target: MeshBasis, C: np.ndarray, *, k_end: int, step: int,
                       n_zoomout: int | None, all_target_vertices: bool) -> tuple[np.ndarray, np.ndarray]:
    """ZoomOut, then the target vertex of every template sample: (C (k_end, k_end), (s,) int)."""
    C = zoomout.zoomout(source, target, C, k_end=k_end, step=step, n_source=n_zoomout, n_target=n_zoomout,
                        all_target_vertices=all_target_vertices)
    ks, kt = C.shape
    cands = np.arange(target.n) if all_target_vertices else target.samples
    match = fmaps.p2p_from_fmap(C, source.evecs[source.samples, :ks], target.evecs[cands, :kt],
                                cells=target.vertex_cells() if all_target_vertices else None)
    return C, cands[match]


def average_geodesic_distance(basis: MeshBasis, *, n_sources: int = 32) -> np.ndarray:
    """Average geodesic distance / sqrt(area) of every vertex to ``n_sources`` farthest-point samples: (n,)."""
    return basis.distances(basis.samples[:n_sources]).mean(axis=0)


def _ring_max(values: np.ndarray, F: np.ndarray, rings: int) -> np.ndarray:
    """Largest value within ``rings`` edges of each vertex: values (n,), F (m,3) -> (n,)."""
    A = vertex_adjacency(F, len(values)).tocsr()
    out = np.asarray(values, dtype=np.float64).copy()
    starts, idx = A.indptr, A.indices
    for _ in range(rings):
        nb = np.maximum.reduceat(out[idx], starts[:-1]) if len(idx) else out
        has = np.diff(starts) > 0
        out = np.where(has, np.maximum(out, nb), out)
    return out


def extremities(basis: MeshBasis, *, max_points: int = 6, radius: float = 0.25, n_sources: int = 64,
                neighbourhood: float = 0.1, min_level: float = 0.3) -> np.ndarray:
    """Feature points: local maxima of the average geodesic distance (AGD), far apart (Lipman & Funkhouser 2009
    use such extremal points; on a body they are hands, feet and head).

    A vertex qualifies when its AGD is the largest within ``neighbourhood`` (units sqrt(area), counted in edge
    rings of the mean edge length), it is at
    least ``radius`` (units sqrt(area), geodesic) from every point already taken, and its AGD is above
    ``min(AGD) + min_level * (max(AGD) - min(AGD))``. Points are taken in decreasing AGD (ties: lowest id).

    Returns: (p,) int vertex ids, p <= max_points, decreasing AGD.
    """
    agd = average_geodesic_distance(basis, n_sources=n_sources)
    E = basis.V[basis.F[:, [1, 2, 0]]] - basis.V[basis.F]
    mean_edge = float(np.linalg.norm(E, axis=2).mean()) / basis.scale
    rings = max(1, int(round(neighbourhood / mean_edge)))
    is_max = agd >= _ring_max(agd, basis.F, rings)
    level = agd.min() + min_level * (agd.max() - agd.min())
    order = np.lexsort((np.arange(basis.n), -agd))
    taken: list[int] = []
    nearest = np.full(basis.n, np.inf)
    for v in order:
        if len(taken) >= max_points or agd[v] < level:
            break
        if not is_max[v] or nearest[v] < radius:
            continue
        taken.append(int(v))
        nearest = np.minimum(nearest, basis.point_distances([v])[0])
    return np.array(taken, dtype=np.int64)


def ranked_assignments(D_source: np.ndarray, D_target: np.ndarray, *, keep: int = 6,
                       scale_invariant: bool = False) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Injective assignments between two small point sets ranked by geodesic distortion.

    Args: D_source: (p, p), D_target: (q, q) pairwise geodesic distances / sqrt(area); min(p, q) >= 3; p, q <= 7.
        scale_invariant: compare the source distances with the assigned target distances times
            mean(source distances) / mean(target distances) of the assigned points (a body that is globally
            thinner or bent -- shorter geodesics at the same area -- then ranks the assignments as an isometric
            one would; without it every assignment of such a pair costs about the same).
    Returns: up to ``keep`` (source index (r,), target index (r,), mean |distance difference|), best first,
        r = min(p, q) (all source points when p <= q).
    """
    p, q = len(D_source), len(D_target)
    r = min(p, q)
    if r < 3:
        raise ValueError(f"need at least 3 feature points on each mesh, got {p} and {q}")
    if max(p, q) > 7:
        raise ValueError("at most 7 feature points per mesh (the assignment search is exhaustive)")
    results = []
    src_sets = [np.arange(p)] if p <= q else [np.array(c) for c in permutations(range(p), r)
                                                 if list(c) == sorted(c)]
    iu = np.triu_indices(r, 1)
    for s in src_sets:
        Ds = D_source[np.ix_(s, s)][iu]
        for t in permutations(range(q), r):
            t = np.array(t)
            Dt = D_target[np.ix_(t, t)][iu]
            if scale_invariant:
                Dt = Dt * (Ds.mean() / max(Dt.mean(), 1e-300))
            results.append((s, t, float(np.mean(np.abs(Ds - Dt)))))
    results.sort(key=lambda x: (x[2], tuple(x[0]), tuple(x[1])))
    return results[:keep]


def _tangent_frames(N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangent vectors (p,3), (p,3) with (t1, t2, n) right-handed, for unit normals N (p,3)."""
    helper = np.where(np.abs(N[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    t1 = np.cross(helper, N)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(N, t1)


def orientation_agreement(source: MeshBasis, target: MeshBasis, p2p_samples: np.ndarray, *,
                          neighbours: int = 16) -> float:
    """How much a map keeps the surface orientation, in [-1, 1] (+1: orientation-preserving, -1: a mirror map).

    At every template sample, the map's local linear part is fitted (least squares) from the sample's
    ``neighbours`` nearest samples (3D), both sides expressed in right-handed tangent frames (t1, t2, outward
    normal); its determinant is positive when the map keeps the orientation. Returns the mean sign.
    """
    X = source.V[source.samples]
    Y = target.V[np.asarray(p2p_samples)]
    _, nb = cKDTree(X).query(X, k=min(neighbours + 1, len(X)))
    nb = nb[:, 1:]
    s1, s2 = _tangent_frames(source.normals()[source.samples])
    r1, r2 = _tangent_frames(target.normals()[np.asarray(p2p_samples)])
    P = X[nb] - X[:, None, :]                                           # (p, k, 3)
    Q = Y[nb] - Y[:, None, :]
    P2 = np.stack([np.einsum("pkc,pc->pk", P, s1), np.einsum("pkc,pc->pk", P, s2)], axis=2)   # (p, k, 2)
    Q2 = np.stack([np.einsum("pkc,pc->pk", Q, r1), np.einsum("pkc,pc->pk", Q, r2)], axis=2)
    # A = (P2^T P2)^-1 P2^T Q2; sign(det A) = sign(det(P2^T Q2)) because det(P2^T P2) > 0
    return float(np.mean(np.sign(np.linalg.det(np.einsum("pki,pkj->pij", P2, Q2)))))


def hks_disagreement(source: MeshBasis, target: MeshBasis, p2p_samples: np.ndarray, *, n_times: int = 16) -> float:
    """Mean relative difference of the heat kernel signatures (template's time scale on both meshes) between the
    template samples and their images: it tells the front of a body from its back, which orientation does not
    (the 180-degree turn swapping left/right *and* front/back preserves orientation)."""
    from corr_core.correspondence import descriptors as desc

    target = in_size_of(target, source)                 # at the template's size (basis.in_size_of)
    times = desc.hks_times(source.evals, n_times=n_times)
    hs = desc.hks(source.evals, source.evecs[source.samples], times=times)
    ht = desc.hks(target.evals, target.evecs[p2p_samples], times=times)
    return float(np.mean(np.abs(hs - ht) / np.maximum(np.abs(hs) + np.abs(ht), 1e-300)))


def chirality_agreement(source: MeshBasis, p2p_samples: np.ndarray, chirality_source: np.ndarray,
                        chirality_target: np.ndarray) -> float:
    """Correlation, in [-1, 1], of the template's chirality functions at its samples with the target's at their
    images: > 0 when the map keeps the orientation *as the assigned points see it*, < 0 for a mirror map.

    Args: p2p_samples: (s,) int target vertex of each of the first s template samples; chirality_source:
        (n_s, P), chirality_target: (n_t, P) ``fmaps.chirality_functions`` of corresponding points (same order).
    Chirality functions vary at the scale of the body, not of the sample spacing, so unlike
    ``orientation_agreement`` (local linear fits) the measure holds on a coarse probe map.
    """
    cs = chirality_source[source.samples[:len(p2p_samples)]]
    ct = chirality_target[np.asarray(p2p_samples)]
    return float(np.sum(cs * ct) / max(np.sqrt(np.sum(cs**2) * np.sum(ct**2)), 1e-300))


def wks_disagreement(source: MeshBasis, target: MeshBasis, p2p_samples: np.ndarray, *, n_energies: int = 50,
                     variance: float = 6.0) -> float:
    """Mean relative difference |w_S - w_T| / (w_S + w_T) of the wave kernel signatures (Aubry et al. 2011) of the
    template samples and of their images, both on the *template's* log-energy bands (the target's eigenvalues
    rescaled by its area / the template's, and the eigenfunctions normalized to unit mean square, so a scaled
    copy has the same signature): (len(p2p_samples),) -> float.

    The WKS separates frequencies better than the HKS (band-pass, not low-pass), so the small intrinsic
    differences between the front and the back of a body (face, chest, feet) show in it; the map that agrees best
    is the least distorted one in that sense. Descriptors cannot tell a mirror map: see ``orientation_agreement``.
    """
    first = int(np.flatnonzero(source.evals > 1e-8 * max(float(source.evals.max()), 1.0))[0])
    log_s = np.log(source.evals[first:])
    energies = np.linspace(log_s[0], log_s[-1] / 1.02 if log_s[-1] > 0 else log_s[-1], n_energies)
    sigma = variance * (energies[1] - energies[0])

    def signature(basis: MeshBasis, rows: np.ndarray, evals: np.ndarray) -> np.ndarray:
        keep = evals > 1e-8 * max(float(evals.max()), 1.0)
        bands = np.exp(-(energies[None, :] - np.log(evals[keep])[:, None]) ** 2 / (2 * sigma**2))   # (k, E)
        phi2 = basis.area * basis.evecs[rows][:, keep] ** 2      # area-normalized: a scaled copy's are equal
        return (phi2 @ bands) / np.maximum(bands.sum(axis=0), 1e-300)

    ws = signature(source, source.samples[:len(p2p_samples)], source.evals)
    wt = signature(target, np.asarray(p2p_samples), target.evals * (target.area / source.area))
    return float(np.mean(np.abs(ws - wt) / np.maximum(ws + wt, 1e-300)))


def cached_extremities(basis: MeshBasis) -> np.ndarray:
    """``extremities(basis)`` computed once per basis (``MeshBasis.cached``; a template reuses them for every
    target, and ``to_arrays`` keeps them): (p,) int local ids."""
    return basis.cached("extremities", lambda: extremities(basis))


def map_automatic(source: MeshBasis, target: MeshBasis, points_source: np.ndarray | None = None,
                  points_target: np.ndarray | None = None, *, keep: int = 4, k_init: int = 40, k_probe: int = 60,
                  k_end: int = 100, step: int = ZOOMOUT_STEP, n_probe: int = 1000, orientation_neighbours: int = 64,
                  return_info: bool = False):
    """A map with no point given on the target (module docstring): the best ranked of
    ``automatic_hypotheses``.

    Args:
        points_source, points_target: feature points of each mesh, original ids (default ``extremities`` of each).
        keep: candidate assignments evaluated as maps (probes: ZoomOut up to ``k_probe`` on ``n_probe`` samples
            of each mesh; the chosen one then goes on to ``k_end`` as ``map_from_points`` does).
        orientation_neighbours: samples per local fit in ``orientation_agreement`` (a probe is coarser than the
            sample spacing, so the local fits need more than the nearest few samples).
    Returns: (C, p2p_samples) as ``map_from_points``; with ``return_info`` also a dict ("points_source",
        "points_target", "chosen": the assigned points, "candidates": every ``Candidate`` with its orientation
        agreement and HKS disagreement filled in).
    """
    out = automatic_hypotheses(source, target, n=1, points_source=points_source, points_target=points_target,
                               keep=keep, k_init=k_init, k_probe=k_probe, k_end=k_end, step=step, n_probe=n_probe,
                               orientation_neighbours=orientation_neighbours, return_info=return_info)
    return (*out[0][0], out[1]) if return_info else out[0]


@dataclass(frozen=True)
class Candidate:
    """One automatic starting map (``automatic_hypotheses``): which feature points it assigned and how it scores.

    source, target: (a,) int positions into the two meshes' feature points, assigned pairwise; cost: the
    assignment's geodesic distortion; C: (k_s, k_t) its probe functional map; p2p: (n_probe,) int its probe point
    map (local target ids of the template's probe samples); chirality: ``chirality_agreement`` (< 0: mirrored);
    wks: ``wks_disagreement``; orientation, hks: reported only (``return_info``), not used by the choice."""
    source: np.ndarray
    target: np.ndarray
    cost: float
    C: np.ndarray
    p2p: np.ndarray
    chirality: float
    wks: float
    orientation: float | None = None
    hks: float | None = None


def hypotheses_to_refine(chirality, wks, *, keep_fraction: float = CHIRALITY_POOL,
                         wks_ratio: float = HYPOTHESIS_WKS_RATIO, at_least: int = MIN_HYPOTHESES,
                         at_most: int = MAX_HYPOTHESES) -> int:
    """How many of the ranked candidates (``rank_candidates`` order) to refine: at least ``at_least`` (when there
    are that many), plus those in the chirality pool whose WKS disagreement is within ``wks_ratio`` times the
    best's, at most ``at_most``.

    Args: chirality, wks: (c,) float the candidates' ``Candidate.chirality`` and ``Candidate.wks``, best first.
    """
    chirality, wks = np.asarray(chirality, dtype=np.float64), np.asarray(wks, dtype=np.float64)
    if not len(chirality):
        return 0
    best = chirality.max()
    close = [i for i in range(len(chirality)) if best > 0 and chirality[i] > keep_fraction * best
             and wks[i] <= wks_ratio * wks[0]]
    n = max([min(at_least, len(chirality))] + [i + 1 for i in close])
    return int(min(n, at_most, len(chirality)))


def automatic_hypotheses(source: MeshBasis, target: MeshBasis, n: int | None = None,
                         points_source: np.ndarray | None = None,
                         points_target: np.ndarray | None = None, *, keep: int = 4, k_init: int = 40,
                         k_probe: int = 60, k_end: int = 100, step: int = ZOOMOUT_STEP, n_probe: int = 1000,
                         orientation_neighbours: int = 64, chirality_weight: float = CHIRALITY_WEIGHT,
                         return_info: bool = False):
    """The best ranked automatic maps (``rank_candidates``: ``map_automatic``'s choice first, then the next in the
    same order), each taken on to ``k_end``: ``n`` of them, or when ``n`` is None as many as
    ``hypotheses_to_refine`` decides (the best two, more when they are close). The true map and the 180-degree
    turn of a body whose front and back look alike both come out, and ``refine.refine_best`` keeps the one that
    refines to the less distorted map. Arguments as ``map_automatic``; ``chirality_weight``: ``point_features``'
    (the probes' chirality columns; a benchmark sweeps it, ``bench/dense_constants.py``).

    Returns: [(C, p2p_samples)] (at most n, best ranked first); with ``return_info`` also ``map_automatic``'s dict.
    """
    if n is not None and int(n) < 1:
        raise ValueError(f"automatic_hypotheses: n must be >= 1 (or None: decided here), got {n}")
    target = in_size_of(target, source)                 # at the template's size (basis.in_size_of)
    Ps = (cached_extremities(source) if points_source is None
          else source.to_local(points_source, what="template point"))
    Pt = extremities(target) if points_target is None else target.to_local(points_target, what="target point")
    few = [f"the {what} has {len(P)}" for what, P in (("template", Ps), ("target", Pt)) if len(P) < 3]
    if few:
        raise ValueError(f"the automatic initialisation needs at least 3 feature points (extremities) on each mesh; "
                         f"{' and '.join(few)} (a mesh this small or this round has no distinct extremities)")
    Gs, Gt = source.point_distances(Ps), target.point_distances(Pt)      # (p, n_s), (q, n_t): kept on the bases
    Ds, Dt = 0.5 * (Gs[:, Ps] + Gs[:, Ps].T), 0.5 * (Gt[:, Pt] + Gt[:, Pt].T)
    candidates = ranked_assignments(Ds, Dt, keep=keep, scale_invariant=True)
    info = {"points_source": Ps, "points_target": Pt, "candidates": []}
    for s, t, cost in candidates:
        # the target's distance fields in the template's units (same mean distance between the assigned points)
        ratio = Ds[np.ix_(s, s)].sum() / max(Dt[np.ix_(t, t)].sum(), 1e-300)
        FS = kept_point_features(source, Ps[s], chirality_weight=chirality_weight)    # from Gs's rows
        FT = point_features(target, Pt[t], distances=ratio * Gt[t], chirality_weight=chirality_weight)
        n_pairs = len(s) * (len(s) - 1) // 2                     # the last columns: the chirality functions
        C, p2p = map_from_points(source, target, source.vids[Ps[s]], target.vids[Pt[t]], k_init=k_init,
                                 k_end=min(k_probe, k_end), step=5, features=(FS, FT), n_zoomout=n_probe,
                                 all_target_vertices=False)
        reported = {}
        if return_info:                                          # reported only: not used by the choice
            reported = {"orientation": orientation_agreement(source, target, p2p, neighbours=orientation_neighbours),
                        "hks": hks_disagreement(source, target, p2p)}
        info["candidates"].append(Candidate(
            s, t, float(cost), C, p2p, chirality=chirality_agreement(source, p2p, FS[:, -n_pairs:], FT[:, -n_pairs:]),
            wks=wks_disagreement(source, target, p2p), **reported))
    ranked = rank_candidates(info["candidates"])
    n_kept = hypotheses_to_refine([c.chirality for c in ranked], [c.wks for c in ranked]) if n is None else int(n)
    ranked = ranked[:n_kept]
    s, t = ranked[0].source, ranked[0].target
    info["chosen"] = (Ps[s], Pt[t])
    maps = [_zoomout_and_match(source, target, c.C, k_end=k_end, step=step, n_zoomout=ZOOMOUT_SAMPLES,
                               all_target_vertices=True) for c in ranked]
    return (maps, info) if return_info else maps


def rank_candidates(candidates: list[Candidate], *, keep_fraction: float = CHIRALITY_POOL) -> list[Candidate]:
    """Candidates best first: those that keep the assigned points' orientation (chirality agreement above
    ``keep_fraction`` of the best candidate's, and > 0) by increasing WKS disagreement, then the others by
    decreasing chirality agreement.

    A mirror map's agreement is < 0; a map right on part of the body and mirrored elsewhere (only the hands or
    only the feet swapped: a twist) keeps a fraction of it (0.32-0.89 of the best on generated bodies, see
    ``CHIRALITY_POOL``: the pool drops the clearest twists only); the true map and the orientation-preserving
    180-degree turn keep most of it, and the descriptors (then the refined maps' distortion) decide."""
    best = max(c.chirality for c in candidates)
    in_pool = [best > 0 and c.chirality > keep_fraction * best for c in candidates]
    pool = sorted((c for c, ok in zip(candidates, in_pool) if ok), key=lambda c: c.wks)
    rest = sorted((c for c, ok in zip(candidates, in_pool) if not ok), key=lambda c: -c.chirality)
    return pool + rest


