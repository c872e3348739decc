"""Pointwise steps after ZoomOut: full-resolution upsampling and refinements below ZoomOut's floor.

ZoomOut works in a truncated spectral basis and has a floor of its own (from the *true* map it ends near one edge
length of mean error on the course SCAPE poses), and it leaves low-frequency mistakes that it cannot see: a
twisted limb, a head turned about its axis, a slid knee. The refinements here work on vertices directly:

``refine_extrinsic`` (first default step): patch-wise rigid ICP. Each small template patch (a geodesic disc of about
0.1 sqrt(area)) is fitted rigidly to its current images *robustly* (pairs far from the patch's consensus are
dropped, so a patch that is partly wrong starts from the transform of its right part), then aligned by ICP
(trimmed point-to-point). Every template vertex is moved by its patch's transform and takes the nearest target
vertex whose normal agrees with its moved normal (a touching body part faces the other way and is never used),
anywhere on the target (not only near its current image, so a region that was 0.1 sqrt(area) off comes back in
a few rounds). Rounds repeat until the map stops changing.

``refine_spectral`` (second default step): ZoomOut at full resolution with local candidates. On the 20 course
SCAPE poses it leaves the mean error as it is and makes the landmarks safer (an elbow that ICP slid up the arm
comes back); on non-isometric bodies (generated humanoid, ``vary_bodies``) it raises the error (ZoomOut assumes
an isometry): use ``refine="extrinsic"`` there. ``refine_geodesic``: pick anchors (farthest-point template
samples) and their current images on the target; compute geodesic distances from the anchors on both meshes
(heat method); move every template vertex to the target vertex, among the ``n_candidates`` nearest (in 3D) to
its current image, whose distances to the images of its ``n_near`` nearest anchors best match its own distances
to those anchors (least squares) -- a local trilateration for (near-)isometric pairs; on request only (it was
worse than ``refine_extrinsic`` on SCAPE). The third default step, ``deform.refine_deform`` (ARAP registration),
lives in its own module; ``refine_map`` runs any of them in order.

``refine_best`` refines several hypothesis maps (``init.automatic_hypotheses``) and keeps the one whose
refined map is least distorted (``map_distortion``).
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.spatial import cKDTree

from corr_core.correspondence.dense import init
from corr_core.correspondence.dense.basis import MeshBasis, in_size_of, map_to_local
from corr_core.correspondence.dense.deform import keep_points, refine_deform, refine_settle
from corr_core.correspondence.dense.fmaps import fmap_from_p2p
from corr_core.correspondence.dense.nearest import PointTree, nearest_compatible, vertex_neighbourhoods
from corr_core.geometry.primitives import unique_edges


def _local_spectral_match(emb_s: np.ndarray, emb_t: np.ndarray, cands: np.ndarray) -> np.ndarray:
    """Among each row's candidates (n_s, c) int, the target vertex whose embedding row (n_t, d) is nearest to the
    template vertex's embedding row (n_s, d): (n_s,) int (ties: the first candidate)."""
    emb_s = emb_s.astype(np.float32)
    emb_t = emb_t.astype(np.float32)
    out = np.empty(len(cands), dtype=np.int64)
    for s in range(0, len(cands), _MATCH_ROWS):
        c = cands[s:s + _MATCH_ROWS]
        diff = emb_t[c]                                                  # (b, c, d), squared in place
        diff -= emb_s[s:s + _MATCH_ROWS, None, :]
        diff *= diff
        out[s:s + _MATCH_ROWS] = c[np.arange(len(c)), np.argmin(diff.sum(axis=2), axis=1)]
    return out


# Rows per block of _local_spectral_match: a block (128 rows x 32 candidates x 100 dims in float32, 1.6 MB) stays
# in cache, and squared in place it needs no temporary; each row's sum is the same, bit for bit, in any block size.
_MATCH_ROWS = 128


def refine_spectral(source: MeshBasis, target: MeshBasis, p2p: np.ndarray, *, k: int | None = None,
                    iterations: int = 5, n_candidates: int = 32) -> np.ndarray:
    """ZoomOut at full resolution and fixed ``k``, with local candidates (cost independent of n_s * n_t).

    Each round fits the least-squares functional map of the current map on *every* template vertex (``k`` basis
    functions, default all the bases have), then moves each template vertex to the target vertex, among the
    ``n_candidates`` nearest (3D) to its current image, nearest in the adjoint spectral embedding
    (``fmaps.p2p_from_fmap``). It removes the quantization of a map known at samples and the small slides the
    extrinsic refinement leaves along smooth surfaces. Stops early when the map no longer changes.

    Args: source, target: bases; p2p: (n_s,) int current map (local ids). Returns (n_s,) int.
    """
    p2p = np.asarray(p2p, dtype=np.int64).copy()
    k = int(min(k or source.evecs.shape[1], source.evecs.shape[1], target.evecs.shape[1]))
    neighbourhoods = vertex_neighbourhoods(target, n_candidates)
    for _ in range(iterations):
        C = fmap_from_p2p(p2p, source.evecs[:, :k], target.evecs[:, :k])
        cands = neighbourhoods.of(p2p)
        new = _local_spectral_match(source.evecs[:, :k], target.evecs[:, :k] @ C.T, cands)
        if np.array_equal(new, p2p):
            break
        p2p = new
    return p2p


def upsample_spectral(source: MeshBasis, target: MeshBasis, C: np.ndarray, p2p_samples: np.ndarray,
                      *, n_candidates: int = 32) -> np.ndarray:
    """Point map of every template vertex from a map known at the template samples and a functional map.

    Each template vertex starts at the image of its nearest template sample (3D) and then takes, among the
    ``n_candidates`` target vertices nearest (3D) to that image, the one nearest in the adjoint spectral embedding
    of ``C`` (the ZoomOut point map restricted to a neighbourhood; exact brute force would cost n_s * n_t * k).

    Args:
        source, target: bases; C: (k_s, k_t) functional map (template x target).
        p2p_samples: (len(source.samples),) int target vertex of each template sample (same order).
        n_candidates: neighbourhood size on the target.
    Returns: (n_s,) int target vertex ids.
    """
    target = in_size_of(target, source)                 # at the template's size (basis.in_size_of)
    samples = source.samples[:len(p2p_samples)]
    _, nearest_sample = cKDTree(source.V[samples]).query(source.V)
    start = np.asarray(p2p_samples)[nearest_sample]
    cands = vertex_neighbourhoods(target, n_candidates).of(start)           # (n_s, c)
    ks, kt = C.shape
    return _local_spectral_match(source.evecs[:, :ks], target.evecs[:, :kt] @ C.T, cands)


def refine_geodesic(source: MeshBasis, target: MeshBasis, p2p: np.ndarray, *, n_anchors: int = 100,
                    n_near: int = 12, n_candidates: int = 32, iterations: int = 3, min_anchor_distance: float = 0.02,
                    source_anchor_distances: np.ndarray | None = None) -> np.ndarray:
    """Geodesic trilateration refinement of a dense map (module docstring).

    Args:
        source, target: bases; p2p: (n_s,) int current target vertex of each template vertex.
        n_anchors: number of anchors (the first farthest-point samples of the template).
        n_near: anchors used per vertex (its geodesically nearest ones beyond ``min_anchor_distance``).
        n_candidates: target vertices considered per template vertex (3D nearest to its current image).
        iterations: rounds (anchor images are updated between rounds).
        min_anchor_distance: anchors closer than this (units sqrt(area)) are skipped for a vertex: the heat
            method smooths distances near the source.
        source_anchor_distances: optional (n_anchors, n_s) template distances from the anchors / sqrt(area),
            to reuse across targets (``source.distances(source.samples[:n_anchors])``).
    Returns: (n_s,) int refined map.
    """
    p2p = np.asarray(p2p, dtype=np.int64).copy()
    anchors = source.samples[:n_anchors]
    D_s = source.distances(anchors) if source_anchor_distances is None else source_anchor_distances
    if D_s.shape != (len(anchors), source.n):
        raise ValueError(f"source_anchor_distances must be ({len(anchors)}, {source.n}), got {D_s.shape}")
    n_near = min(n_near, len(anchors))
    far = np.where(D_s >= min_anchor_distance, D_s, np.inf)
    near = np.argsort(far, axis=0, kind="stable")[:n_near].T              # (n_s, n_near) anchor indices
    d_src = np.take_along_axis(D_s.T, near, axis=1)                        # (n_s, n_near)
    neighbourhoods = vertex_neighbourhoods(target, n_candidates)
    for _ in range(iterations):
        D_t = target.distances(p2p[anchors]).T                              # (n_t, n_anchors)
        cands = neighbourhoods.of(p2p)                                       # (n_s, c)
        new = np.empty_like(p2p)
        for s in range(0, source.n, 2048):
            c = cands[s:s + 2048]                                             # (b, c)
            nr = near[s:s + 2048]                                             # (b, n_near)
            dt = D_t[c[:, :, None], nr[:, None, :]]                           # (b, c, n_near)
            cost = np.sum((dt - d_src[s:s + 2048, None, :]) ** 2, axis=2)
            new[s:s + 2048] = c[np.arange(len(c)), np.argmin(cost, axis=1)]
        if np.array_equal(new, p2p):
            break
        p2p = new
    return p2p


def _kabsch_batch(X: np.ndarray, Y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted rigid fits, batched: X, Y: (b,p,3), w: (b,p) >= 0 -> R (b,3,3), t (b,3) minimizing
    sum_i w_i |R x_i + t - y_i|^2 per batch entry (reflections excluded)."""
    w = w / np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    mx = np.einsum("bp,bpc->bc", w, X)
    my = np.einsum("bp,bpc->bc", w, Y)
    H = np.einsum("bp,bpi,bpj->bij", w, X - mx[:, None], Y - my[:, None])
    U, _, Wt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("bji,bkj->bik", Wt, U)))       # det(W U^T)
    D = np.zeros_like(H)
    D[:, 0, 0] = 1.0
    D[:, 1, 1] = 1.0
    D[:, 2, 2] = np.where(d == 0, 1.0, d)
    R = np.einsum("bji,bjk,blk->bil", Wt, D, U)                        # W D U^T
    return R, my - np.einsum("bij,bj->bi", R, mx)


def _robust_kabsch_batch(X: np.ndarray, Y: np.ndarray, *, iterations: int = 4, cutoff: float = 2.5
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Rigid fits X (b,p,3) -> Y (b,p,3) that ignore wrong pairs: refit ``iterations`` times on the pairs whose
    residual is within ``cutoff`` x the patch's median residual. Returns R (b,3,3), t (b,3). A patch whose current
    images are partly wrong (a jump, a slide) then starts from the transform of its right part."""
    w = np.ones(X.shape[:2])
    for _ in range(iterations):
        R, t = _kabsch_batch(X, Y, w)
        r = np.linalg.norm(np.einsum("bij,bpj->bpi", R, X) + t[:, None, :] - Y, axis=2)
        w = (r <= cutoff * np.median(r, axis=1, keepdims=True) + 1e-12).astype(float)
    return R, t


def refine_extrinsic(source: MeshBasis, target: MeshBasis, p2p: np.ndarray, *, n_patches: int = 300,
                     patch_size: int = 64, icp_iterations: int = 6, rounds: int = 5, trim: float = 2.0,
                     n_candidates: int | None = None, normal_cos: float = -1.0, partners: str = "plane"
                     ) -> np.ndarray:
    """Local rigid alignment (patch-wise ICP) of the template onto the target, then nearest vertices.

    A body moves almost rigidly at the scale of a small patch, so each template patch -- the ``patch_size``
    template samples geodesically nearest to one of the first ``n_patches`` farthest-point samples (about a
    geodesic disc of radius sqrt(patch_size / (pi * n_samples)) sqrt(area)) -- is aligned to the target: a robust
    rigid fit to its current images (``_robust_kabsch_batch``: pairs far off the patch's consensus are dropped),
    then ``icp_iterations`` of ICP against the nearest target vertices (pairs farther than ``trim``
    x the patch's median distance get no weight; ``normal_cos`` > -1 also requires the moved template normal and
    the target normal to make a cosine above it -- off by default: it did not help on the course SCAPE poses and
    made the coarse generated humanoid worse, the trimming already drops such pairs). A point's ICP partner is its
    nearest target vertex projected onto that vertex's tangent plane (``partners="plane"``, point-to-plane ICP: a
    patch then slides along the surface instead of snapping to the vertices, which matters on a target coarser
    than the template) or the vertex itself (``partners="vertex"``, the older point-to-point ICP). Every template
    vertex is moved by the transform of its geodesically nearest patch centre and takes
    the nearest normal-compatible target vertex (cosine > 0) to its moved position (``n_candidates`` = an int
    restricts it instead to the ``n_candidates`` target vertices nearest to its current image, the older
    behaviour: it cannot move more than a few edges a round). ``rounds`` repeats this from the new map.
    Template geodesics come from ``source.sample_distances`` (cached, once per template); the target needs none.

    ``n_patches`` 300 (for 2,000 samples; the pipelines at 1,000 samples use 150) and ``patch_size`` 64: swept by
    `python bench/dense_constants.py --seeds 10-13` (generated other bodies, 20 targets; docs/dense.md "Tuned
    constants"): at 1,000 samples 75 to 300 patches give mean errors 0.01290 to 0.01302 on the right maps; patch
    sizes 64 and 96 0.01301 and 0.01293, 128 and 192 worse (0.01382, 0.01958), 32 too (0.01546 against 0.01325
    on the 18 maps right at both, and one more flip), so both stay.

    Point-to-plane partners: on the remeshed course poses (`python bench/correspondence.py --pairs 20 --methods
    dense_sparse,dense_auto --data /tmp/scape_remeshed`) mean errors 0.0109 / 0.0113 against 0.0113 / 0.0116 with
    the vertices, on the course poses 0.0095 / 0.0098 against 0.0096 / 0.0101, at the same time (at 3040154,
    before 344693e's exact near ties; docs/dense.md "Point-to-plane ICP").

    Args: source, target: bases; p2p: (n_s,) int current map. Returns (n_s,) int refined map.
    """
    if partners not in ICP_PARTNERS:
        raise ValueError(f"refine_extrinsic: partners must be one of {ICP_PARTNERS}, got {partners!r}")
    p2p = np.asarray(p2p, dtype=np.int64).copy()
    n_patches = min(n_patches, len(source.samples))
    patch_size = min(patch_size, len(source.samples))
    owner, members = _patches(source, n_patches, patch_size)
    X = source.V[members]                                            # (b, p, 3)
    N_s, N_t = source.normals(), target.normals()
    tree = target.tree()
    for _ in range(rounds):
        R, t = _robust_kabsch_batch(X, target.V[p2p[members]])
        for _ in range(icp_iterations):
            moved = np.einsum("bij,bpj->bpi", R, X) + t[:, None, :]
            j, d = _icp_pairs(tree, N_t, moved, N_s[members], R, normal_cos)
            finite = np.isfinite(d)
            med = _finite_row_median(d, finite)
            w = (finite & (d <= trim * med + 1e-12)).astype(float)
            R, t = _kabsch_batch(X, _icp_targets(target, N_t, moved, j, partners), w)
        new = _assign(tree, target, p2p, np.einsum("nij,nj->ni", R[owner], source.V) + t[owner],
                      np.einsum("nij,nj->ni", R[owner], N_s), N_t, n_candidates)
        if np.array_equal(new, p2p):
            break
        p2p = new
    return p2p


def _patches(source: MeshBasis, n_patches: int, patch_size: int) -> tuple[np.ndarray, np.ndarray]:
    """``refine_extrinsic``'s patches of the template, made once per basis (every starting map of a target gets
    the step): the nearest patch centre of every vertex (n_s,) int and the members of every patch
    (n_patches, patch_size) int vertex ids, the template samples geodesically nearest to its centre."""
    def make() -> tuple[np.ndarray, np.ndarray]:
        D_c = source.sample_distances(n_patches)                    # (n_patches, n_s)
        owner = np.argmin(D_c, axis=0)
        near = np.argsort(D_c[:, source.samples], axis=1, kind="stable")[:, :patch_size]
        return _read_only(owner), _read_only(source.samples[near])
    return source.cached(("patches", n_patches, patch_size), make)


def _read_only(a: np.ndarray) -> np.ndarray:
    """``a``, no longer writable: an array cached on a basis is shared by every later call."""
    a.setflags(write=False)
    return a


def _icp_pairs(tree: PointTree, normals_t: np.ndarray, moved: np.ndarray, patch_normals: np.ndarray, R: np.ndarray,
               normal_cos: float) -> tuple[np.ndarray, np.ndarray]:
    """ICP partners of the moved patch points (b,p,3): target ids (b,p) int and distances (b,p) float (inf: no
    compatible partner). ``normal_cos`` <= -1: no normal test, the plain nearest vertex (one k-d tree query per
    point instead of the ``nearest.nearest_compatible`` search among 8)."""
    shape = moved.shape[:2]
    if normal_cos <= -1.0:
        d, j = tree.query(moved.reshape(-1, 3))
    else:
        normals = np.einsum("bij,bpj->bpi", R, patch_normals)
        j, d = nearest_compatible(tree, normals_t, moved.reshape(-1, 3), normals.reshape(-1, 3),
                                  min_cos=normal_cos)
    return j.reshape(shape), d.reshape(shape)


ICP_PARTNERS = ("plane", "vertex")          # ``refine_extrinsic``'s ICP partners


def _icp_targets(target: MeshBasis, normals_t: np.ndarray, moved: np.ndarray, j: np.ndarray, partners: str
                 ) -> np.ndarray:
    """Where the moved patch points (b,p,3) are pulled to: their partner vertices j (b,p) int (``"vertex"``) or
    each point's projection onto the tangent plane of its partner (``"plane"``: v + (I - n n^T)(x - v), with the
    unit vertex normal n), (b,p,3) float."""
    Y = target.V[j]
    if partners == "vertex":
        return Y
    N = normals_t[j]
    return moved - np.einsum("bpc,bpc->bp", moved - Y, N)[..., None] * N


def _finite_row_median(d: np.ndarray, finite: np.ndarray) -> np.ndarray:
    """Median of the finite entries of each row of d (b,p) -> (b,1); 0 for a row with none."""
    if finite.all():
        return np.median(d, axis=1, keepdims=True)
    return np.array([np.median(row[ok]) if ok.any() else 0.0 for row, ok in zip(d, finite)])[:, None]


def _assign(tree: PointTree, target: MeshBasis, p2p: np.ndarray, moved: np.ndarray, moved_normals: np.ndarray,
            normals_t: np.ndarray, n_candidates: int | None) -> np.ndarray:
    """Target vertex of every moved template vertex (n_s,3): the nearest normal-compatible one (None), or the
    nearest among the ``n_candidates`` nearest to the current image; the current image where none qualifies."""
    if n_candidates is None:
        new, d = nearest_compatible(tree, normals_t, moved, moved_normals, min_cos=0.0)
        return np.where(np.isfinite(d), new, p2p)
    cands = vertex_neighbourhoods(target, n_candidates).of(p2p)
    d = np.linalg.norm(target.V[cands] - moved[:, None, :], axis=2)
    return cands[np.arange(len(p2p)), np.argmin(d, axis=1)]



# The default plan. On bodies of other people "extrinsic+spectral?+deform" (the spectral step kept only where it
# lowers the distortion) or "extrinsic+deform" are more accurate, on poses of one body less: docs/dense.md
# "Refinement plan" (`python bench/refine_plans.py --seeds 10-13` and the pipelines' results).
DEFAULT_REFINE = "extrinsic+spectral+deform"
_MAP_ARGUMENTS = ("source", "target", "p2p", "points")    # what refine_map passes to the steps itself
ONLY_IF_LOWER = "?"                                    # a step's name ending so: kept only where it lowers distortion


@dataclass(frozen=True)
class RefineStep:
    """One pointwise refinement step: ``name`` a key of ``REFINE_STEPS``, ``options`` keyword arguments of its
    function (checked against the function's parameters when the step is made, so a misspelt option fails before
    any work), ``only_if_lower``: its result is kept only when its ``map_distortion`` is lower than the map's it
    started from (else the step leaves the map as it was); written as the name followed by "?" ("spectral?").
    ``RefineStep("deform", {"stiffness": 0.02})``."""
    name: str
    options: Mapping[str, Any] = field(default_factory=dict)
    only_if_lower: bool = False

    def __post_init__(self):
        if self.name.endswith(ONLY_IF_LOWER):
            object.__setattr__(self, "name", self.name[:-len(ONLY_IF_LOWER)])
            object.__setattr__(self, "only_if_lower", True)
        if self.name not in REFINE_STEPS:
            raise ValueError(f"unknown refinement step {self.name!r}; the steps are {list(REFINE_STEPS)} (a name "
                             f"followed by {ONLY_IF_LOWER!r}: kept only where it lowers the distortion)")
        takes = [p for p in inspect.signature(REFINE_STEPS[self.name]).parameters if p not in _MAP_ARGUMENTS]
        unknown = sorted(set(self.options) - set(takes))
        if unknown:
            raise ValueError(f"refinement step {self.name!r}: unknown option(s) {unknown}; it takes {takes}")
        object.__setattr__(self, "options", dict(self.options))

    @property
    def takes_points(self) -> bool:
        """Whether the step's function is constrained by given points (its ``points`` argument: the
        registrations "deform" and "settle")."""
        return "points" in inspect.signature(REFINE_STEPS[self.name]).parameters

    def run(self, source: MeshBasis, target: MeshBasis, p2p: np.ndarray,
            points: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """This step applied to ``p2p`` (n_s,) int local ids: the refined (n_s,) int map (``p2p`` itself when the
        step is ``only_if_lower`` and does not lower the distortion). The step sees the target in the template's
        size (``basis.in_size_of``: its positions are compared with the template's). ``points``: given
        corresponding points (template local ids (p,) int, target local ids (p,) int): a step that takes them
        (the registrations: constraints) gets them, and every step's map sends them to their target points."""
        extra = {"points": points} if points is not None and self.takes_points else {}
        refined = REFINE_STEPS[self.name](source, in_size_of(target, source), p2p, **self.options, **extra)
        if points is not None:
            refined = keep_points(refined, points)
        if self.only_if_lower and not map_distortion(source, target, refined) < map_distortion(source, target, p2p):
            return p2p
        return refined


def refine_plan(refine: str | Sequence | None = DEFAULT_REFINE,
                options: Mapping[str, Mapping] | None = None) -> tuple[RefineStep, ...]:
    """The typed steps of a refinement written as users write it.

    Args:
        refine: None or "none" (no step); names of ``REFINE_STEPS`` joined by "+" in the order they run (the form
            of the pipelines' YAML, e.g. ``DEFAULT_REFINE``; a name followed by "?", "spectral?": the step is kept
            only where it lowers the distortion); or a sequence of names and ``RefineStep``s.
        options: {step name: keyword arguments} given to every step of that name (a ``RefineStep``'s own options
            win). Options of a step the plan does not run are allowed (a stage passes every step's options); an
            option key that names no step is an error.
    Returns: the steps, in order.
    """
    options = dict(options or {})
    unknown = sorted(set(options) - set(REFINE_STEPS))
    if unknown:
        raise ValueError(f"refine options name no refinement step: {unknown}; the steps are {list(REFINE_STEPS)}")
    if refine is None or refine == "none":
        return ()
    if isinstance(refine, str):
        refine = refine.split("+")
    elif not isinstance(refine, Sequence):
        raise ValueError(f"refine must be None, 'none', steps of {list(REFINE_STEPS)} joined by '+' (e.g. "
                         f"{DEFAULT_REFINE!r}) or a list of steps, got {refine!r}")
    steps = []
    for step in refine:
        if isinstance(step, RefineStep):
            steps.append(RefineStep(step.name, {**options.get(step.name, {}), **step.options}, step.only_if_lower))
        elif isinstance(step, str):
            steps.append(RefineStep(step, options.get(step.removesuffix(ONLY_IF_LOWER), {})))
        else:
            raise ValueError(f"a refinement step is a name of {list(REFINE_STEPS)} or a RefineStep, got {step!r}")
    return tuple(steps)


def refine_map(source: MeshBasis, target: MeshBasis, p2p: np.ndarray,
               refine: str | Sequence | None = DEFAULT_REFINE, options: Mapping | None = None, *,
               points: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The pointwise refinements of ``refine_plan(refine, options)``, in order (``DEFAULT_REFINE``
    "extrinsic+spectral+deform" is the default of ``dense_map`` and of the ``corr.dense_refine`` stage).

    Args: source, target: bases; p2p: (n_s,) int current map (local ids); refine, options: as ``refine_plan``;
        points: given corresponding points (template, target local ids, (p,) int each) the map keeps
        (``RefineStep.run``), or None.
    Returns: (n_s,) int refined map.
    """
    for step in refine_plan(refine, options):
        p2p = step.run(source, target, p2p, points)
    return p2p


def _log_ratio_spread(length_a: np.ndarray, length_b: np.ndarray) -> float:
    """Mean absolute deviation, from its median, of log(length_b / length_a) over the pairs where both are > 0
    (inf where none is): 0 for lengths equal up to one scale."""
    kept = (length_a > 0) & (length_b > 0)
    if not kept.any():
        return float("inf")
    log_ratio = np.log(length_b[kept] / length_a[kept])
    return float(np.mean(np.abs(log_ratio - np.median(log_ratio))))


def _edges(basis: MeshBasis) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's unique edges (e,2) int and their lengths (e,) float, cached on the basis (a template's serve every
    target and hypothesis)."""
    def edges_and_lengths() -> tuple[np.ndarray, np.ndarray]:
        edges, _ = unique_edges(basis.F)
        return edges, np.linalg.norm(basis.V[edges[:, 0]] - basis.V[edges[:, 1]], axis=1)
    return basis.cached("edges", edges_and_lengths)


def _mean_edge(basis: MeshBasis) -> float:
    """Mean edge length / sqrt(area) of a mesh: its resolution in the unit the distortion compares."""
    return float(np.mean(_edges(basis)[1])) / basis.scale


def _forward_distortion(source: MeshBasis, target: MeshBasis, p2p: np.ndarray) -> float:
    """Spread of log edge-length ratios over the template edges, their ends taken to their target vertices."""
    edges, length_s = _edges(source)
    length_t = np.linalg.norm(target.V[p2p[edges[:, 0]]] - target.V[p2p[edges[:, 1]]], axis=1)
    return _log_ratio_spread(length_s, length_t)


def _backward_distortion(source: MeshBasis, target: MeshBasis, p2p: np.ndarray) -> float:
    """Spread of log edge-length ratios over the target edges whose two ends are images, each end taken back to
    the mean position of the template vertices mapped onto it (a continuous preimage: on a target coarser than
    the template several template vertices share a target vertex)."""
    count = np.bincount(p2p, minlength=target.n).astype(float)
    preimage = np.column_stack([np.bincount(p2p, weights=source.V[:, c], minlength=target.n) for c in range(3)])
    hit = count > 0
    preimage[hit] /= count[hit, None]
    edges, length_t = _edges(target)
    both = hit[edges[:, 0]] & hit[edges[:, 1]]
    edges, length_t = edges[both], length_t[both]
    length_s = np.linalg.norm(preimage[edges[:, 0]] - preimage[edges[:, 1]], axis=1)
    return _log_ratio_spread(length_t, length_s)


def map_distortion(source: MeshBasis, target: MeshBasis, p2p: np.ndarray) -> float:
    """How far a dense map is from a local similarity: the mean absolute deviation, from its median, of the log
    ratio of edge lengths and their images, over the edges of the *coarser* of the two meshes (larger mean edge /
    sqrt(area); the target on a tie).

    A near-isometric map keeps edge lengths up to one scale; a map that twists a limb (the 180-degree turn of a
    body, forced to keep its feet pointing forward) shears it and scores higher. The coarser mesh's edges make it
    independent of the two meshes' densities: measured on the finer mesh's edges, whose images or preimages
    land on the coarser mesh's vertices, the quantization (about one coarse edge on every image) hides the
    twist -- on a generated body decimated to half its vertices the true map and the turn scored 0.307 and 0.304
    on the template's edges, 0.197 and 0.201 on the target's (``python bench/dense_hypotheses.py --seeds 0-9
    --decimated``, docs/dense.md "Confidence"). Template edges: ``_forward_distortion``; target edges:
    ``_backward_distortion`` (each target vertex taken back to the mean of the template vertices mapped onto it).

    Args: source, target: bases; p2p (n_s,) int local target ids. Returns: float >= 0 (inf: no usable edge).
    """
    p2p = np.asarray(p2p, dtype=np.int64)
    if _mean_edge(target) >= _mean_edge(source):
        return _backward_distortion(source, target, p2p)
    return _forward_distortion(source, target, p2p)


POINTS_TOLERANCE = 0.1   # units sqrt(target area): a given point's image this close to its given target counts


def points_agreement(target: MeshBasis, p2p: np.ndarray, points: tuple[np.ndarray, np.ndarray], *,
                     tolerance: float = POINTS_TOLERANCE) -> float:
    """Fraction of the given points that a dense map keeps: template point i's image is within ``tolerance``
    (3D distance / sqrt(target area)) of target point i. The confidence of a map made from given points (a map
    turned or mirrored against them scores near 0).

    Args: p2p (n_s,) int local target ids; points: (template ids (L,) int, target ids (L,) int), local,
        corresponding (as ``refine_map(points=)``).
    """
    points_source, points_target = (np.asarray(ids, dtype=np.int64) for ids in points)
    images = target.V[np.asarray(p2p)[points_source]]
    gap = np.linalg.norm(images - target.V[points_target], axis=1) / target.scale
    return float(np.mean(gap <= tolerance)) if len(gap) else float("nan")


MIN_POINTS_KEPT = 0.8     # another map replaces the one made from given points only if it keeps this many of them


def best_with_points(source: MeshBasis, target: MeshBasis, maps: list, points: tuple[np.ndarray, np.ndarray], *,
                     min_kept: float = MIN_POINTS_KEPT, known_distortions: Sequence[float | None] = ()) -> BestMap:
    """The least distorted of several refined maps (``map_distortion``) among those that keep the given points:
    ``maps[0]`` (the map made from them) always qualifies, any other one (e.g. the automatic map of the same pair)
    when ``points_agreement`` >= ``min_kept``. So given points never make a map worse than the automatic one when
    that one agrees with them (points placed a little off on a scan pull the map made from them).

    Args: maps: [(n_s,) int local ids], refined; points: (template ids (L,) int, target ids (L,) int), local;
        known_distortions: ``map_distortion`` of the first maps when already computed (None: not known).
    Returns: ``BestMap`` over the qualifying maps (distortions of the others: inf).
    """
    if not len(maps):
        raise ValueError("best_with_points: no map given")
    known = list(known_distortions) + [None] * (len(maps) - len(known_distortions))

    def score(i: int, m: np.ndarray) -> float:
        if i and points_agreement(target, m, points) < min_kept:
            return float("inf")
        return known[i] if known[i] is not None else map_distortion(source, target, m)

    scores = tuple(score(i, m) for i, m in enumerate(maps))
    best = int(np.argmin(scores))
    return BestMap(np.asarray(maps[best]), best, scores)


def with_alternative(source: MeshBasis, target: MeshBasis, best: BestMap, alternative: np.ndarray,
                     points: tuple[np.ndarray, np.ndarray], refine: str | Sequence | None = None) -> BestMap:
    """``best`` (the refined map made from given points) or ``alternative``, the less distorted once both are held.

    Args: best: ``refine_best``'s result for the map made from the points; alternative: (n_s original,) int another
        dense map of the same pair in original ids (-1 off the kept component), e.g. the automatic one;
        points: (template ids (L,) int, target ids (L,) int), local, the given points; refine: the plan that refined
        ``best`` with the points held (``refine_best(points=)``), or None: the two compared as they come
        (``best_with_points``).
    With a plan, an alternative that keeps the given points (``points_agreement`` >= ``MIN_POINTS_KEPT``, read on
    the alternative as given) and ``best`` both get the plan's registration once more with the points held
    (``hold_points``), and the less distorted of the two held maps is kept (a tie keeps ``best``). Holding a map
    runs the registration once more, which lowers its distortion and its error: holding only the alternative
    favoured it (on the course poses it then replaced maps from the points that were more accurate), and comparing
    the two as they came kept, on 2 of the default pipeline's 6 poses, the map from the points that was less
    distorted by a hair but less accurate than the automatic one (docs/dense.md "Given points never hurt"). An
    alternative that does not keep the points is not refined, and ``best`` is returned as it is.
    Returns: ``BestMap`` of the two (index 1: the alternative was kept; distortions: of the held maps, inf for an
        alternative that does not keep the points).
    """
    other = map_to_local(source, target, alternative)
    if refine is None:
        return best_with_points(source, target, [best.p2p, other], points,
                                known_distortions=(best.distortions[best.index],))
    if points_agreement(target, other, points) < MIN_POINTS_KEPT:
        return BestMap(np.asarray(best.p2p), 0, (best.distortions[best.index], float("inf")))
    held = [hold_points(source, target, m, refine, points) for m in (best.p2p, other)]
    scores = tuple(map_distortion(source, target, m) for m in held)
    kept = int(np.argmin(scores))
    return BestMap(held[kept], kept, scores)


def own_points_start(source: MeshBasis, target: MeshBasis, p2p: np.ndarray, *, k_init: int = 40,
                     k_end: int = 100) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]] | None:
    """The map made from a map's own points, before refinement: the template's feature points
    (``init.cached_extremities``) and their images under ``p2p`` (n_s,) int local, taken as given points and
    mapped as the sparse mode maps them (``init.map_from_points``, ``k_init`` / ``k_end`` as there, then
    ``upsample_spectral``). Returns (start (n_s,) int local, (template points (p,), target points (p,)) local), or
    None when fewer than 3 distinct images (``map_from_points`` needs 3 points)."""
    P = init.cached_extremities(source)
    images = np.asarray(p2p)[P]
    if len(P) < 3 or len(np.unique(images)) < len(P):
        return None
    C, samples_map = init.map_from_points(source, target, source.vids[P], target.vids[images], k_init=k_init,
                                          k_end=k_end)
    return upsample_spectral(source, target, C, samples_map), (P, images)


def second_opinion(source: MeshBasis, target: MeshBasis, best: BestMap, refine: str | Sequence | None = DEFAULT_REFINE,
                   options: Mapping | None = None, *, k_init: int = 40, k_end: int = 100) -> BestMap:
    """``best`` (an automatic map) or the map made from its own feature points, whichever is less distorted.

    The map of ``own_points_start(best.p2p)``, refined by the plan with its points held (``refine_map(points=)``),
    replaces ``best.p2p`` when its ``map_distortion`` is lower. The automatic start continues a coarse probe's
    functional map and can leave a limb slid that the refinement shrinks without removing; the images of the
    feature points under the refined map are closer to the truth than the points detected on the target
    (docs/dense.md "A second opinion from the automatic map's own points"). No ground truth is used.
    Returns: ``best``, or a copy of it with the other map as ``p2p`` (the choice among hypotheses, its index,
        distortions and confidence stay ``best``'s).
    """
    start = own_points_start(source, target, best.p2p, k_init=k_init, k_end=k_end)
    if start is None:
        return best
    other = refine_map(source, target, start[0], refine, options, points=start[1])
    if map_distortion(source, target, other) < map_distortion(source, target, best.p2p):
        return replace(best, p2p=other)
    return best


def hold_points(source: MeshBasis, target: MeshBasis, p2p: np.ndarray, refine: str | Sequence | None,
                points: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """A refined map p2p (n_s,) int made to hold given points as ``refine_map(refine, points=points)`` holds them:
    the plan's steps that take the points (the registrations, "deform" / "settle") run again with them, and the map
    sends them to their target points (``keep_points``). Returns (n_s,) int."""
    for step in refine_plan(refine):
        if step.takes_points:
            p2p = step.run(source, target, p2p, points)
    return keep_points(p2p, points)


# The distortion margin at which a kept map counts as sure (confidence 1): the runner-up hypothesis refined to a
# map this much (relative) more distorted. On generated bodies (`python bench/dense_hypotheses.py --seeds 0-9
# --candidates 2`, docs/dense.md "Confidence") the kept map beat the runner-up by a median 0.25 (least 0.046), and
# was never the wrong one: a judged value below most margins, so a sure choice reads 1 and a tie 0.
CONFIDENT_MARGIN = 0.10
LOW_CONFIDENCE = 0.5     # below this a map is reported for a look (half the margin of a sure choice)
# ``refine_best`` drops a hypothesis after the first refinement step only when it is this much (relative) more
# distorted than the least distorted one there. The first step judges less surely than the whole plan: on 217
# generated targets of other bodies (`python bench/dense_hypotheses.py --seeds S --candidates 3 --decimated`,
# seeds 0-9 and 13-33; docs/dense.md "Confidence") the right map was once 1 / (1 - 0.151) = 1.178 times the least
# distorted one after the first step (seed 23's pose 6: dropped at the former margin, 10 %, a flip reported with
# confidence 1) and came out the least distorted at the end; 0.3 leaves room above that.
DROP_MARGIN = 0.30
# After a later step (not the last), a hypothesis whose ``refinement_score`` so far is this much (relative) above the
# least one's is dropped too. By then the steps judge more surely than the first alone. On the same 217 generated
# targets (`python bench/dense_hypotheses.py --seeds 0-9 --candidates 3 --decimated` and `--seeds 13-33`,
# 2026-12-03; docs/dense.md "Confidence"), the right map's score after the first two steps was at most 1.057 times
# the least one's (1.000 on seeds 0-9); after the first step alone it was up to 1.178 times. The same choices were
# made with 95 hypotheses fewer refined to the end, and none flipped. 0.15 leaves room above the 1.057 seen, and
# spares the last step (``refine_deform``, the costliest after the first) most runner-ups the first step kept.
LATER_DROP_MARGIN = 0.15
# Before that: after the first round of the first step (``refine_extrinsic``'s 5 rounds; the rest of the step then
# continues the survivors, the same maps bit for bit: a round starts from the map alone), a hypothesis this much
# (relative) more distorted than the least distorted one is dropped, saving it the step's other rounds. One round
# judges less surely than the step: on 238 generated targets (`python bench/dense_hypotheses.py --seeds 0-16
# --candidates 3 --decimated` and `--seeds 17-33`, 2026-12-08, docs/dense.md "Confidence") the right map was at
# most 1.496 times the least distorted one after one round (1.427 on 2026-12-02); 0.65 leaves 10 % above that, as
# the other margins do, and drops 21 of the 368 runner-ups there, never the kept map.
EARLY_DROP_MARGIN = 0.65


@dataclass(frozen=True)
class BestMap:
    """The result of ``refine_best``: p2p (n_s,) int local ids of the kept refined map, index: its position among
    the hypotheses, distortions: ``map_distortion`` of every hypothesis after the last step it was refined by
    (same order), dropped: which hypotheses were dropped before the last step (empty: none), step_distortions:
    every hypothesis's ``map_distortion`` after each step it got (empty when none was dropped; () for one dropped
    after the first round of the first step), scores: what the choice compared (``refinement_score``; empty: the
    distortions), early: every hypothesis's ``map_distortion`` after that first round (empty: not measured)."""
    p2p: np.ndarray
    index: int
    distortions: tuple[float, ...]
    dropped: tuple[bool, ...] = ()
    step_distortions: tuple[tuple[float, ...], ...] = ()
    scores: tuple[float, ...] = ()
    early: tuple[float, ...] = ()

    @property
    def margin(self) -> float:
        """(runner-up's score - kept one's) / kept one's: >= 0, each other hypothesis compared with the kept
        one on the same footing (a dropped one: their ``refinement_score`` over the steps it got, where it was
        dropped; one dropped after the first round: their distortions then); inf with a single hypothesis (nothing
        to compare with) or a kept map of zero distortion."""
        scores = self.scores or self.distortions
        margins = []
        for i, d in enumerate(scores):
            if i == self.index:
                continue
            kept, other = scores[self.index], d
            if self.dropped and self.dropped[i]:
                got = len(self.step_distortions[i])
                if got == 0:                                  # dropped after the first round of the first step
                    kept, other = self.early[self.index], self.early[i]
                else:
                    kept = refinement_score(self.step_distortions[self.index][:got])
                    other = refinement_score(self.step_distortions[i])
            margins.append((other - kept) / kept if kept > 0 else float("inf"))
        return float(min(margins)) if margins else float("inf")

    @property
    def confidence(self) -> float:
        """How sure the choice among the hypotheses is, in [0, 1], without ground truth: margin / CONFIDENT_MARGIN,
        capped at 1. Near 0: another hypothesis (e.g. the body turned by 180 degrees or mirrored) refined to an
        almost equally good map, so the kept one may be flipped. NaN with a single hypothesis."""
        if len(self.distortions) < 2:
            return float("nan")
        return float(min(1.0, self.margin / CONFIDENT_MARGIN))


def surviving_hypotheses(first_step: Sequence[float], *, drop_margin: float = DROP_MARGIN) -> list[int]:
    """The hypotheses worth refining further: those whose distortion after the first step (``map_distortion``,
    (h,) floats) is within ``drop_margin`` (relative) of the least one's. Returns their indices, in order."""
    least = min(first_step)
    return [i for i, d in enumerate(first_step) if d <= (1.0 + drop_margin) * least]


def surviving_after_step(step_distortions: Sequence[Sequence[float]], alive: Sequence[int], *,
                         drop_margin: float = DROP_MARGIN, later_margin: float = LATER_DROP_MARGIN) -> list[int]:
    """Which of the hypotheses ``alive`` go on to the next step. step_distortions: every hypothesis's
    ``map_distortion`` after each step it got (the alive ones: the same number s >= 1 of steps). After the first
    step: ``surviving_hypotheses`` of those distortions at ``drop_margin``; after a later one: of their
    ``refinement_score`` so far at ``later_margin``. Returns the surviving indices (a subset of ``alive``), in
    order."""
    alive = list(alive)
    if len(alive) < 2:
        return alive
    got = {len(step_distortions[i]) for i in alive}
    if len(got) != 1:
        raise ValueError(f"surviving_after_step: the alive hypotheses got different numbers of steps {sorted(got)}")
    if got == {1}:
        kept = surviving_hypotheses([step_distortions[i][0] for i in alive], drop_margin=drop_margin)
    else:
        kept = surviving_hypotheses([refinement_score(step_distortions[i]) for i in alive], drop_margin=later_margin)
    return [alive[j] for j in kept]


def refinement_score(step_distortions: Sequence[float]) -> float:
    """What ``refine_best`` compares between hypotheses refined to the end: the geometric mean of a map's
    ``map_distortion`` after each step of the plan ((s,) floats, s >= 1; one step: that distortion).

    Why not the last one alone: the later steps smooth a wrong map (a body turned by 180 degrees) nearly as well as
    the right one, so its last distortion can come out a little lower, while after the earlier steps it was
    clearly higher. On 217 generated targets of other bodies (docs/dense.md "Confidence", the line "flips when every
    hypothesis is refined to the end" of ``bench/dense_hypotheses.py``) the last distortion alone kept 2 flipped
    maps (both reported with low confidence), this score none."""
    values = np.asarray(step_distortions, dtype=np.float64)
    if not len(values):
        raise ValueError("refinement_score: no distortion given")
    if len(values) == 1:
        return float(values[0])
    if np.any(values <= 0):                  # an undistorted step: nothing beats it
        return 0.0
    return float(np.exp(np.mean(np.log(values))))          # inf when some step's distortion is inf


def best_refined(maps: Sequence[np.ndarray], step_distortions: Sequence[Sequence[float]], *,
                 alive: Sequence[int] | None = None, early: Sequence[float] = ()) -> BestMap:
    """The choice ``refine_best`` makes among refined hypotheses: the lowest ``refinement_score`` among those
    refined to the end (ties to the earlier one).

    Args: maps: h refined maps ((n_s,) int local ids); step_distortions: h sequences, each hypothesis's
        ``map_distortion`` after every step it got (a dropped one: those before it was dropped); alive: the
        indices refined to the end (``surviving_after_step``; None: all); early: every hypothesis's distortion
        after the first round of the first step, when measured (a hypothesis dropped there has no step
        distortion: this one is its distortion).
    Returns: ``BestMap`` (dropped and step_distortions recorded when some hypothesis was dropped).
    """
    alive = range(len(maps)) if alive is None else alive
    early = tuple(float(d) for d in early)
    distortions = tuple(float(s[-1]) if len(s) else early[i] for i, s in enumerate(step_distortions))
    scores = tuple(refinement_score(s) if i in alive else float("inf") for i, s in enumerate(step_distortions))
    best = min(alive, key=lambda i: (scores[i], i))
    dropped = tuple(i not in alive for i in range(len(maps)))
    if not any(dropped):
        return BestMap(maps[best], best, distortions, scores=scores, early=early)
    steps = tuple(tuple(float(d) for d in s) for s in step_distortions)
    return BestMap(maps[best], best, distortions, dropped, steps, scores, early)


def refine_best(source: MeshBasis, target: MeshBasis, maps: list,
                refine: str | Sequence | None = DEFAULT_REFINE, options: Mapping | None = None, *,
                drop_margin: float = DROP_MARGIN, later_margin: float = LATER_DROP_MARGIN,
                early_margin: float = EARLY_DROP_MARGIN,
                points: tuple[np.ndarray, np.ndarray] | None = None) -> BestMap:
    """Refine each of several hypothesis maps (``refine_map``) and keep the best: the lowest
    ``refinement_score`` (geometric mean of the distortion after each step).

    Every hypothesis gets the plan's first step (when that is ``extrinsic`` and no points are given: its first
    round, then the rest of it for those whose distortion after that round is within ``early_margin`` of the least
    one's, ``first_round_split``: the others are dropped already); one then more distorted than the least distorted by more than
    ``drop_margin`` (relative: already surely beaten, ``surviving_hypotheses``) is dropped, the others get the
    next step; after each later step but the last, one whose ``refinement_score`` so far is more than
    ``later_margin`` above the least is dropped too (``surviving_after_step``).

    Args: maps: [(n_s,) int local ids], e.g. the upsampled maps of ``init.automatic_hypotheses``; points: given
        corresponding points every refined map keeps (``refine_map``), or None.
    Returns: ``BestMap`` (the kept refined map, its index in ``maps``, every hypothesis's ``map_distortion``, which
    were dropped; its ``confidence`` says how clear the choice was). Ties go to the earlier hypothesis (the better
    ranked one).
    """
    if not len(maps):
        raise ValueError("refine_best: no hypothesis map given")
    plan = refine_plan(refine, options)
    if len(maps) == 1 or len(plan) <= 1:
        refined = [refine_map(source, target, m, plan, points=points) for m in maps]
        return best_refined(refined, [[map_distortion(source, target, m)] for m in refined])
    ahead, early = list(range(len(maps))), ()
    # with given points every part of a step keeps them (RefineStep.run): the split would no longer be the step
    split = first_round_split(plan[0]) if points is None else None
    if split is None:
        refined = [plan[0].run(source, target, m, points) for m in maps]
    else:               # the first round for all, the rest of the step for those not already beaten
        refined = [split[0].run(source, target, m, points) for m in maps]
        early = tuple(map_distortion(source, target, m) for m in refined)
        ahead = surviving_hypotheses(early, drop_margin=early_margin)
        refined = [split[1].run(source, target, m, points) if i in ahead else m for i, m in enumerate(refined)]
    steps = [[map_distortion(source, target, m)] if i in ahead else [] for i, m in enumerate(refined)]
    alive = surviving_after_step(steps, ahead, drop_margin=drop_margin, later_margin=later_margin)
    for k, step in enumerate(plan[1:], start=2):
        for i in alive:
            refined[i] = step.run(source, target, refined[i], points)
            steps[i].append(map_distortion(source, target, refined[i]))
        if k < len(plan):
            alive = surviving_after_step(steps, alive, drop_margin=drop_margin, later_margin=later_margin)
    return best_refined(refined, steps, alive=alive, early=early)


def first_round_split(step: RefineStep) -> tuple[RefineStep, RefineStep] | None:
    """``step`` as its first round and the rest, when it is an ``extrinsic`` step of several rounds (not
    ``only_if_lower``): (the step with ``rounds`` 1, the step with the other rounds); run one after the other they
    give ``step.run``'s map bit for bit (each round starts from the map alone, and a round that changes nothing
    ends the step, as it ends the rest at once). None for any other step."""
    if step.name != "extrinsic" or step.only_if_lower:
        return None
    rounds = step.options.get("rounds", inspect.signature(REFINE_STEPS["extrinsic"]).parameters["rounds"].default)
    if rounds < 2:
        return None
    return RefineStep("extrinsic", {**step.options, "rounds": 1}), RefineStep("extrinsic", {**step.options,
                                                                                            "rounds": rounds - 1})


REFINE_STEPS = {"extrinsic": refine_extrinsic, "spectral": refine_spectral, "deform": refine_deform,
                "settle": refine_settle, "geodesic": refine_geodesic}   # the steps ``refine_map`` runs, by name
