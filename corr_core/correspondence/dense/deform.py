"""Non-rigid registration of the template onto the target (as-rigid-as-possible), read back as a point map.

``refine_deform`` deforms the template surface X (starting at the current images of its vertices) by
alternating the two steps of ARAP (Sorkine & Alexa 2007): best local rotations of every vertex's edge fan, then
one sparse linear solve for X that keeps the edges close to the rotated template edges while a data term pulls
every vertex toward (a) its current image (the map so far; pairs far off the median are dropped as wrong) and
(b) the tangent plane of its nearest target vertex whose normal agrees (closest-point, point-to-plane, as in
non-rigid ICP; a touching body part faces the other way and is ignored). The data weight per vertex is its
area over (``stiffness`` sqrt(area))^2: detail smaller than about ``stiffness`` follows the target, motion on
larger scales follows the template's shape, so a vertex cannot slide away from its neighbours the way a
nearest-vertex step (``refine_extrinsic``) or a truncated spectral basis (``refine_spectral``) lets it. Each
template vertex finally takes the nearest normal-compatible target vertex to its deformed position.

Units: positions in the meshes' units; ``stiffness`` in units of sqrt(template area).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from corr_core.correspondence.dense.basis import MeshBasis
from corr_core.correspondence.dense.nearest import nearest_compatible
from corr_core.geometry.primitives import vertex_normals


def arap_operators(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, sp.csr_matrix, np.ndarray]:
    """Edges, weights and matrices of the ARAP energy of a mesh.

    Args: V: (n,3) float; F: (m,3) int.
    Returns: edges (e,2) int (i < j, the couplings of the cotan Laplacian), weights (e,) float >= 0 (cotan
        weights, negative ones clipped: they make the energy indefinite), stiffness (n,n) sparse graph Laplacian
        of those weights, mass (n,) float vertex areas (units of V squared).
    """
    from corr_core.geometry.laplacian import laplacian_and_mass

    L, M = laplacian_and_mass(V, F)
    L = sp.triu(L, k=1).tocoo()
    edges = np.column_stack([L.row, L.col]).astype(np.int64)
    weights = np.maximum(-L.data, 0.0)
    n = len(V)
    W = sp.coo_matrix((np.r_[weights, weights], (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
                      shape=(n, n)).tocsr()
    K = (sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W).tocsr()
    return edges, weights, K, M.diagonal().copy()


def _incidence(edges: np.ndarray, n: int) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """(n, e) unsigned (both ends +1) and signed (i: +1, j: -1) edge incidence matrices."""
    e = len(edges)
    rows = np.r_[edges[:, 0], edges[:, 1]]
    cols = np.r_[np.arange(e), np.arange(e)]
    unsigned = sp.csr_matrix((np.ones(2 * e), (rows, cols)), shape=(n, e))
    signed = sp.csr_matrix((np.r_[np.ones(e), -np.ones(e)], (rows, cols)), shape=(n, e))
    return unsigned, signed


def _fan_rotations(E0: np.ndarray, E1: np.ndarray, weights: np.ndarray, unsigned: sp.csr_matrix,
                   *, squarings: int = 8) -> np.ndarray:
    """Best rotation of every vertex's edge fan: R_i = argmin sum_j w_ij |e1_ij - R e0_ij|^2 over rotations.

    Horn's quaternion form (1987): the optimal rotation is the top eigenvector of a symmetric 4x4 matrix built
    from the fan's covariance, found here by repeated squaring of that matrix (shifted to be positive definite)
    -- batched 4x4 products, faster than numpy's batched 3x3 SVD here, always a proper rotation. Where the
    top two eigenvalues (nearly) tie the rotation is ill-defined and either answer is as good for ARAP.

    Args: E0, E1: (e,3) template and deformed edge vectors; weights (e,); unsigned (n,e) incidence.
    Returns: (n,3,3) rotations (det +1).
    """
    outer = (weights[:, None, None] * E0[:, :, None] * E1[:, None, :]).reshape(-1, 9)
    S = np.asarray(unsigned @ outer)                                    # (n,9): sum over each vertex's edges
    xx, xy, xz, yx, yy, yz, zx, zy, zz = S.T
    bound = np.sqrt(3.0) * np.linalg.norm(S, axis=1) + 1e-300           # >= |every eigenvalue of N|
    # N's 10 distinct entries (it is symmetric), scaled and shifted to M = N / bound + I: positive semi-definite,
    # N's eigenvectors. Squared entry by entry over all vertices at once (numpy's batched 4x4 products are slower).
    N = {(0, 0): xx + yy + zz, (0, 1): yz - zy, (0, 2): zx - xz, (0, 3): xy - yx, (1, 1): xx - yy - zz,
         (1, 2): xy + yx, (1, 3): zx + xz, (2, 2): -xx + yy - zz, (2, 3): yz + zy, (3, 3): -xx - yy + zz}
    M = {ij: v / bound + (1.0 if ij[0] == ij[1] else 0.0) for ij, v in N.items()}
    for _ in range(squarings):
        M = _squared_over_trace(M)
    start = (1.0, 1e-3, 2e-3, 3e-3)                                     # fixed start: deterministic
    q = np.column_stack([sum(_entry(M, i, j) * start[j] for j in range(4)) for i in range(4)])
    w, x, y, z = (q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-300)).T
    return np.stack([np.stack([w*w + x*x - y*y - z*z, 2 * (x*y - w*z), 2 * (x*z + w*y)], -1),
                     np.stack([2 * (x*y + w*z), w*w - x*x + y*y - z*z, 2 * (y*z - w*x)], -1),
                     np.stack([2 * (x*z - w*y), 2 * (y*z + w*x), w*w - x*x - y*y + z*z], -1)], axis=1)


def _entry(M: dict, i: int, j: int) -> np.ndarray:
    """Entry (i, j) (n,) of symmetric 4x4 matrices given by their 10 distinct entries {(i, j), i <= j: (n,)}."""
    return M[(i, j) if i <= j else (j, i)]


def _squared_over_trace(M: dict) -> dict:
    """M @ M / trace(M @ M) of symmetric 4x4 matrices given by their 10 distinct entries {(i, j), i <= j: (n,)}."""
    P = {(i, j): sum(_entry(M, i, k) * _entry(M, k, j) for k in range(4)) for i in range(4) for j in range(i, 4)}
    trace = np.maximum(P[(0, 0)] + P[(1, 1)] + P[(2, 2)] + P[(3, 3)], 1e-300)
    return {ij: v / trace for ij, v in P.items()}


class TemplateARAP:
    """The template's ARAP operators at one stiffness, factorized once and reused for every target.

    V: (n,3) float, F: (m,3) int template; stiffness: units of sqrt(area); area: the template's surface area
    (default: the sum of its vertex areas).
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, stiffness: float, area: float | None = None):
        self.F = np.asarray(F)
        self.edges, self.weights, K, mass = arap_operators(V, F)
        self.unsigned, self.signed = _incidence(self.edges, len(V))
        area = float(mass.sum()) if area is None else float(area)
        self.lam = mass / (stiffness**2 * area)                          # data weight per vertex
        self.solve = splu(sp.csc_matrix(K + sp.diags(self.lam))).solve
        self.E0 = V[self.edges[:, 0]] - V[self.edges[:, 1]]
        self._pinned: dict = {}

    def pinned_solve(self, pins: np.ndarray):
        """The solve with the vertices ``pins`` (p,) int (distinct) held at given positions: a function
        (rhs (n,) float, at (p,) float) -> (n,) float, the minimizer of the same energy under x[pins] = at
        (Lagrange multipliers through the p columns Z = A^-1 U of the factorized matrix A, made once per pin set)."""
        key = tuple(np.asarray(pins, dtype=np.int64).tolist())
        if key not in self._pinned:
            n = len(self.lam)
            Z = np.column_stack([self.solve(np.eye(1, n, v).ravel()) for v in key])         # (n, p)
            self._pinned[key] = (Z, np.linalg.inv(Z[list(key)]))
        Z, inverse = self._pinned[key]
        rows = list(key)

        def solve(rhs: np.ndarray, at: np.ndarray) -> np.ndarray:
            x = self.solve(rhs)
            return x - Z @ (inverse @ (x[rows] - at))
        return solve

    def register(self, target: "_Target", anchors: np.ndarray, iterations: int, anchor_weight: float,
                 outlier: float, normal_cos: float, pins: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> np.ndarray:
        """One registration from the anchors (n,3) (the current images): ``iterations`` local (fan rotations) /
        global (one factorized solve per coordinate) steps; ``pins`` = (template vertex ids (p,) int, distinct;
        positions (p,3) float): those vertices are held there. Returns the deformed template (n,3)."""
        i, j = self.edges[:, 0], self.edges[:, 1]
        X = anchors.copy()
        if pins is not None:
            X[pins[0]] = pins[1]
            solve = self.pinned_solve(pins[0])
        for it in range(iterations):
            R = _fan_rotations(self.E0, X[i] - X[j], self.weights, self.unsigned)
            rhs = self.signed @ (0.5 * self.weights[:, None] * np.einsum("bij,bj->bi", R[i] + R[j], self.E0))
            goal = (anchors if it == 0 else
                    target.data_goal(X, vertex_normals(X, self.F), anchors, anchor_weight, outlier, normal_cos))
            if pins is None:
                X = np.column_stack([self.solve(rhs[:, c] + self.lam * goal[:, c]) for c in range(3)])
            else:
                X = np.column_stack([solve(rhs[:, c] + self.lam * goal[:, c], pins[1][:, c]) for c in range(3)])
        return X


class _Target:
    """The target's positions (n_t,3), normals and k-d tree, for the data term and the read-back."""

    def __init__(self, basis: MeshBasis):
        self.V = basis.V
        self.normals = basis.normals()
        self.tree = basis.tree()

    def data_goal(self, X: np.ndarray, normals_X: np.ndarray, anchors: np.ndarray, anchor_weight: float,
                  outlier: float, normal_cos: float) -> np.ndarray:
        """Where the data term pulls each deformed vertex X (n,3) (normals (n,3)): a blend of its anchor (current
        image), its projection on the tangent plane of its nearest compatible target vertex, and itself (no pull)
        for the share neither applies to. Returns (n,3)."""
        _, q = self.tree.query(X)
        N = self.normals[q]
        compatible = np.einsum("ij,ij->i", normals_X, N) > normal_cos
        on_plane = X - np.einsum("ij,ij->i", X - self.V[q], N)[:, None] * N
        r = np.linalg.norm(X - anchors, axis=1)
        w_anchor = np.where(r <= outlier * np.median(r) + 1e-12, anchor_weight, 0.0)
        w_plane = np.where(compatible, 1.0 - w_anchor, 0.0)
        w_self = 1.0 - w_anchor - w_plane
        return w_anchor[:, None] * anchors + w_plane[:, None] * on_plane + w_self[:, None] * X

    def nearest_vertices(self, X: np.ndarray, normals_X: np.ndarray, fallback: np.ndarray, *, k: int = 8) -> np.ndarray:
        """Nearest target vertex to each deformed vertex X (n,3) (normals (n,3)) among its ``k`` nearest whose
        normal faces the same side (cosine > 0); ``fallback`` (n,) int where none does."""
        ids, d = nearest_compatible(self.tree, self.normals, X, normals_X, min_cos=0.0, k=k)
        return np.where(np.isfinite(d), ids, fallback)


def refine_deform(source: MeshBasis, target: MeshBasis, p2p: np.ndarray, *, stiffness: float = 0.03,
                  iterations: int = 3, rounds: int = 10, anchor_weight: float = 0.5, outlier: float = 3.0,
                  normal_cos: float = 0.5, points: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """ARAP registration of the template onto the target from the current map (module docstring).

    Args:
        source, target: bases; p2p: (n_s,) int current map (local ids).
        stiffness: length (units sqrt(template area)) below which the data term wins over ARAP. 0.03: swept by
            `python bench/dense_constants.py --seeds 10-13` (generated other bodies; docs/dense.md "Tuned
            constants"): 0.02 and softer raise the error on 18 of 20 targets, 0.04 and 0.05 lower it on 14 of 20
            (mean 0.01271 and 0.01277 against 0.01301 on the right maps), 0.08 raises it; 0.03 stays (the
            pipelines' measured results use it).
        iterations: rotation / solve steps per round.
        rounds: registrations; each starts from the map the previous one read back (its images become the new
            anchors), so a region the anchors held back moves on; stops early when the map no longer changes.
        anchor_weight: share of the data term that pulls a vertex to its current image (the rest pulls it to the
            target surface); images farther than ``outlier`` x the median from the deformed vertex get none.
        normal_cos: closest-point pairs need the deformed normal and the target normal at a cosine above this.
        points: given corresponding points (template local ids (p,) int, target local ids (p,) int) or None:
            each registration holds those template vertices at their target vertices (hard constraints; the
            first of repeated template ids counts) and the map sends them there.
    Returns: (n_s,) int refined map. The template's factorized operators are cached on ``source``.
    """
    if not stiffness > 0 or int(iterations) < 1 or int(rounds) < 1 or not 0 <= anchor_weight <= 1:
        raise ValueError(f"refine_deform: need stiffness > 0, iterations >= 1, rounds >= 1 and 0 <= anchor_weight "
                         f"<= 1, got {stiffness}, {iterations}, {rounds}, {anchor_weight}")
    p2p = np.asarray(p2p, dtype=np.int64)
    arap = source.cached(("arap", float(stiffness)), lambda: TemplateARAP(source.V, source.F, stiffness, source.area))
    tgt = _Target(target)
    pins = None
    if points is not None:
        points = distinct_points(points)
        p2p = keep_points(p2p, points)
        pins = (points[0], target.V[points[1]])
    for _ in range(int(rounds)):
        X = arap.register(tgt, target.V[p2p], int(iterations), anchor_weight, outlier, normal_cos, pins)
        new = tgt.nearest_vertices(X, vertex_normals(X, source.F), p2p)
        if points is not None:
            new = keep_points(new, points)
        if np.array_equal(new, p2p):
            break
        p2p = new
    return p2p


def keep_points(p2p: np.ndarray, points: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """A copy of the map p2p (n_s,) int that sends the given template points (p,) int to their target points (p,)
    int (local ids); a repeated template id goes to its first pair's target, as the registration holds it."""
    source_ids, target_ids = distinct_points(points)
    out = np.array(p2p, dtype=np.int64)
    out[source_ids] = target_ids
    return out


def distinct_points(points: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Given points (template ids (p,) int, target ids (p,) int) with each template id once (its first pair kept)."""
    source_ids = np.asarray(points[0], dtype=np.int64)
    target_ids = np.asarray(points[1], dtype=np.int64)
    if source_ids.shape != target_ids.shape or source_ids.ndim != 1:
        raise ValueError(f"points: two (p,) id arrays of one length, got {source_ids.shape} and {target_ids.shape}")
    _, first = np.unique(source_ids, return_index=True)
    first = np.sort(first)
    return source_ids[first], target_ids[first]


def refine_settle(source: MeshBasis, target: MeshBasis, p2p: np.ndarray, *, stiffness: float = 0.03,
                  iterations: int = 6, rounds: int = 10, normal_cos: float = 0.5,
                  points: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """``refine_deform`` with no pull toward the current images (``anchor_weight`` 0): ARAP against the target
    surface only (point-to-plane onto normal-compatible nearest vertices, i.e. non-rigid ICP), started from the
    current map: refinement step "settle", on request (not a default step). After ``refine_deform`` (whose anchors
    keep a wrong region from dragging its neighbours) it lets the registration slide along the surface to where
    the template keeps its shape best: on generated bodies of other people that lowers the error, on the course
    SCAPE poses it raised it (docs/dense.md "Settling": with nothing holding it, a limb can turn about its own
    axis at almost no ARAP cost). ``python bench/settle_sweep.py --seeds 10 --poses 4``
    (generated other bodies, 4 poses and a decimated copy, from the maps the other steps give) printed mean error
    0.01382 unsettled, 0.01160 with these defaults (6 iterations, stiffness 0.03; lower on 5 of 5 targets), 0.01035
    with 10 iterations (about 1.35x the settling's time; not yet re-measured on the pipelines, docs/dense.md).

    Args: as ``refine_deform``. Returns: (n_s,) int refined map.
    """
    return refine_deform(source, target, p2p, stiffness=stiffness, iterations=iterations, rounds=rounds,
                         anchor_weight=0.0, normal_cos=normal_cos, points=points)
