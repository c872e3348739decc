"""Functional maps (Ovsjanikov et al. 2012) with the orientation-preserving term (Ren et al. 2018).

Convention (used by every module of this package): the template is the *source* S (n_s vertices), the target is
T (n_t vertices); a point map is ``p2p: (n_s,) int``, the target vertex of each template vertex. Its functional
map is the pull-back ``C: (k_s, k_t)``: a target function with coefficients ``a`` (f = Phi_T a) pulls back to
the template function with coefficients ``C a``. So ``Phi_S C ~ Phi_T[p2p]`` (rows: vertices), and the point map
of a functional map is the nearest row of ``Phi_T`` to each row of ``Phi_S C``.

Fit (``fit_functional_map``): least squares in C of
    w_descr  ||C A_T - A_S||^2                        descriptors d_S ~ d_T o p2p (A = Phi^T M d)
  + w_lap    sum_ij (lam_T_j - lam_S_i)^2 C_ij^2      commutativity with the Laplacians
  + w_orient sum_f ||C Om_T(f) - Om_S(f) C||^2        orientation: Om(f) g = <n, grad f x grad g>
each term divided by its typical size (as pyFM's canonical weights) so the weights are comparable. The orientation operator changes sign under
a mirror image, so the term separates a map from its left/right flip; descriptors and the Laplacian cannot.
The problem is quadratic: it is solved exactly by one dense linear system of size k_s * k_t.
"""
from __future__ import annotations

import numpy as np

from corr_core.correspondence.dense.basis import MeshBasis, face_gradients
from corr_core.correspondence.dense.nearest import RowCells
from corr_core.geometry.primitives import face_areas, face_normals


def project(basis: MeshBasis, funcs: np.ndarray, k: int) -> np.ndarray:
    """Spectral coefficients of vertex functions: (n, q) -> (k, q) = Phi[:, :k]^T M funcs."""
    return basis.evecs[:, :k].T @ (basis.mass[:, None] * funcs)


def orientation_operators(basis: MeshBasis, funcs: np.ndarray, k: int, normalize: bool = False) -> np.ndarray:
    """Reduced orientation operators of descriptor functions (Ren et al. 2018, sec. 4).

    Om(f)[i, j] = integral over the surface of phi_i <n, g_f x grad phi_j>, with g_f the per-face gradient of f
    (normalized to unit length with ``normalize``).

    Args: basis: the mesh; funcs: (n, q) descriptor functions; k: basis size.
    Returns: (q, k, k) float.
    """
    V, F = basis.V, basis.F
    Phi = basis.evecs[:, :k]
    G_basis = face_gradients(basis, Phi)                      # (m,3,k)
    G_f = face_gradients(basis, funcs)                        # (m,3,q)
    if normalize:
        G_f /= np.maximum(np.linalg.norm(G_f, axis=1, keepdims=True), 1e-12)
    N = face_normals(V, F)
    W = np.cross(N[:, :, None], G_f, axis=1)                  # (m,3,q): n x g_f
    P = Phi[F].mean(axis=1) * face_areas(V, F)[:, None]       # (m,k): face-mean of phi_i times face area
    Q = np.einsum("mcq,mck->qmk", W, G_basis)                 # (q,m,k): (n x g_f) . grad phi_j
    return np.einsum("mi,qmj->qij", P, Q)


def fit_functional_map(A_S: np.ndarray, A_T: np.ndarray, evals_S: np.ndarray, evals_T: np.ndarray,
                       Om_S: np.ndarray | None = None, Om_T: np.ndarray | None = None, *, w_descr: float = 1.0,
                       w_lap: float = 0.1, w_orient: float = 1.0) -> np.ndarray:
    """Solve the quadratic functional-map energy of the module docstring exactly.

    Args:
        A_S: (k_s, q) template descriptor coefficients; A_T: (k_t, q) target ones (same descriptors, same order).
        evals_S: (>= k_s,) and evals_T: (>= k_t,) eigenvalues (any units; the term is normalized).
        Om_S: (q', k_s, k_s), Om_T: (q', k_t, k_t) orientation operators of corresponding descriptors, or None.
        w_descr, w_lap, w_orient: weights of the three terms.
    Returns:
        C: (k_s, k_t) float.
    """
    ks, kt = A_S.shape[0], A_T.shape[0]
    if A_S.shape[1] != A_T.shape[1]:
        raise ValueError(f"descriptor counts differ: {A_S.shape[1]} vs {A_T.shape[1]}")
    n, m, q = ks * kt, min(ks, kt), A_S.shape[1]
    # Each term is divided by its typical size at a generic map of norm sqrt(m) (pyFM's "canonical" scales).
    # unknown x = vec(C), column-major: x[i + ks * j] = C[i, j]
    # descriptor term ||C A_T - A_S||^2: H += (A_T A_T^T) kron I, b += vec(A_S A_T^T)
    d_scale = max(m * float(np.sum(A_S[1:] ** 2)) / ks / q, 1e-300)
    lap = (evals_T[None, :kt] - evals_S[:ks, None]) ** 2
    l_scale = max(m * float(lap.mean()), 1e-300)
    if Om_S is None or Om_T is None or w_orient <= 0 or not len(Om_S):
        # without the orientation term the rows of C decouple (as in pyFM): row i solves
        # (w_d A_T A_T^T + w_l diag(lap[i])) c_i = w_d A_T A_S[i]^T, ks systems of size kt instead of one of ks * kt
        G = w_descr / d_scale * (A_T @ A_T.T)
        R = w_descr / d_scale * (A_S @ A_T.T)                 # (ks, kt): right-hand sides, one row per row of C
        H_rows = np.repeat(G[None], ks, axis=0)
        H_rows[:, np.arange(kt), np.arange(kt)] += w_lap / l_scale * lap + 1e-12
        return np.linalg.solve(H_rows, R[:, :, None])[:, :, 0]
    H = w_descr / d_scale * np.kron(A_T @ A_T.T, np.eye(ks))
    b = w_descr / d_scale * (A_S @ A_T.T).ravel(order="F")
    H[np.diag_indices(n)] += w_lap / l_scale * lap.ravel(order="F")
    # ||C P - Q C||^2 with P = Om_T (kt x kt), Q = Om_S (ks x ks); vec(C P) = (P^T kron I) x,
    # vec(Q C) = (I kron Q) x; K = P^T kron I - I kron Q; K^T K summed over descriptors.
    nq = len(Om_S)
    o_scale = max(m / (ks * kt) * (kt * float(np.sum(Om_S**2)) + ks * float(np.sum(Om_T**2))) / nq, 1e-300)
    PPt = np.einsum("qij,qkj->ik", Om_T, Om_T)             # sum P P^T (kt x kt)
    QtQ = np.einsum("qji,qjk->ik", Om_S, Om_S)             # sum Q^T Q (ks x ks)
    # (P^T kron I)^T (I kron Q) = P kron Q (its transpose is P^T kron Q^T), summed over descriptors
    cross = (Om_T.reshape(nq, -1).T @ Om_S.reshape(nq, -1)).reshape(kt, kt, ks, ks)
    cross = cross.transpose(0, 2, 1, 3).reshape(kt * ks, kt * ks)
    KtK = np.kron(PPt, np.eye(ks)) + np.kron(np.eye(kt), QtQ) - cross - cross.T
    H += w_orient / o_scale * KtK
    C = np.linalg.solve(H + 1e-12 * np.eye(n), b)
    return C.reshape((ks, kt), order="F")


def fmap_from_p2p(p2p: np.ndarray, Phi_S_rows: np.ndarray, Phi_T: np.ndarray) -> np.ndarray:
    """Least-squares pull-back functional map of a point map given on some template rows.

    Args:
        p2p: (r,) int target vertex of each given template row.
        Phi_S_rows: (r, k_s) template basis at those rows; Phi_T: (n_t, k_t) target basis.
    Returns: C: (k_s, k_t) with Phi_S_rows C ~ Phi_T[p2p].

    Solved by the normal equations (Cholesky of the k_s x k_s Gram matrix: ~10x cheaper than an SVD) when they are
    well conditioned -- eigenvectors at spread samples or at all vertices are nearly orthogonal columns
    (condition number ~1.2 at the course meshes' 2000 samples, ~2 at all vertices) -- else by the SVD-based
    ``numpy.linalg.lstsq`` (few rows, rank-deficient bases).
    """
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    Phi_S_rows = np.asarray(Phi_S_rows, dtype=np.float64)
    rhs = np.asarray(Phi_T, dtype=np.float64)[np.asarray(p2p)]
    if len(Phi_S_rows) >= Phi_S_rows.shape[1]:
        gram = Phi_S_rows.T @ Phi_S_rows
        try:
            factor = cho_factor(gram, lower=True, check_finite=False)
            diag = np.abs(np.diag(factor[0]))
            if diag.min() > 1e-4 * diag.max():                 # cond(gram) < 1e8: the normal equations are safe
                return cho_solve(factor, Phi_S_rows.T @ rhs, check_finite=False)
        except LinAlgError:
            pass
    return np.linalg.lstsq(Phi_S_rows, rhs, rcond=None)[0]


def nearest_rows(queries: np.ndarray, points: np.ndarray, *, chunk: int = 256,
                 cells: RowCells | None = None) -> np.ndarray:
    """Index of the nearest row of ``points`` (p, d) for each row of ``queries`` (q, d) -> (q,) int.

    Brute force in float32 (``|x|^2 - 2 x.y`` by BLAS in blocks of ``chunk`` queries that stay in cache), about
    2.5x faster than float64 on the course meshes (2000 queries among 12,500 points in 100 dimensions); the rows
    whose float32 score is within its rounding bound of the best are then scored again exactly (float64
    differences, ``_nearest_scored``), so the answer is the exact nearest row of the float32 inputs, ties to the
    lowest index, whatever BLAS's kernels round. With ``cells`` (a partition of the points' rows, ``RowCells``)
    the same answer by a pruned search (``_nearest_rows_in_cells``).
    """
    queries = np.ascontiguousarray(queries, dtype=np.float32)
    points = np.ascontiguousarray(points, dtype=np.float32)
    if queries.ndim != 2 or points.ndim != 2 or queries.shape[1] != points.shape[1] or len(points) == 0:
        raise ValueError(f"nearest_rows: need (q, d) queries and (p >= 1, d) points, got {queries.shape} and "
                         f"{points.shape}")
    sq = np.einsum("ij,ij->i", points, points)
    qq = np.einsum("ij,ij->i", queries, queries)
    # |error| of a float32 |y|^2 - 2 x.y <= ~(d + 2) eps (|x|^2 + 2 |y|^2); twice that covers both scores compared
    score_slack = 4.0 * (points.shape[1] + 2) * np.finfo(np.float32).eps * (qq + 2.0 * sq.max())
    if cells is not None:
        if len(cells.owner) != len(points):
            raise ValueError(f"nearest_rows: the cells partition {len(cells.owner)} rows, the points have "
                             f"{len(points)}")
        return _nearest_rows_in_cells(queries, points, sq, qq, score_slack, cells)
    out = np.empty(len(queries), dtype=np.int64)
    for s in range(0, len(queries), chunk):
        out[s:s + chunk] = _nearest_scored(queries[s:s + chunk], points, sq, score_slack[s:s + chunk])
    return out


def _nearest_scored(queries: np.ndarray, points: np.ndarray, sq: np.ndarray, score_slack: np.ndarray) -> np.ndarray:
    """Nearest row of ``points`` (p, d) float32 for each of the (b, d) float32 ``queries`` -> (b,) int.

    Scored by BLAS as ``sq - 2 q.p`` (sq: (p,) the points' squared norms); the rows within ``score_slack`` (b,) of
    a query's best score (float32 rounding) are scored again as float64 squared differences and the least kept,
    ties to the lowest row. BLAS may round one product differently at another place in the matrix (a row at a
    tile's edge goes through another kernel), so only the second scoring makes the answer independent of which
    rows are scored together (the pruned search scores subsets) and of the machine.
    """
    d = queries @ points.T
    d *= -2.0
    d += sq[None, :]
    best = np.argmin(d, axis=1)
    close = d <= (d[np.arange(len(d)), best] + score_slack)[:, None]
    tied = np.flatnonzero(np.count_nonzero(close, axis=1) > 1)
    if len(tied) == 0:
        return best
    q_of, rows = np.nonzero(close[tied])                    # row-major: each query's candidates in ascending order
    exact = np.empty(len(rows))
    step = max(1, (1 << 20) // queries.shape[1])            # 8 MB of float64 differences at a time
    for s in range(0, len(rows), step):
        diff = queries[tied[q_of[s:s + step]]].astype(np.float64) - points[rows[s:s + step]].astype(np.float64)
        exact[s:s + step] = np.einsum("ij,ij->i", diff, diff)
    order = np.lexsort((rows, exact, q_of))                 # per query: least distance, then lowest row
    first = np.flatnonzero(np.r_[True, q_of[order][1:] != q_of[order][:-1]])
    best[tied] = rows[order[first]]
    return best


def _nearest_rows_in_cells(queries: np.ndarray, points: np.ndarray, sq: np.ndarray, qq: np.ndarray,
                           score_slack: np.ndarray, cells: RowCells, *, block: int = 2048,
                           group: int = 32) -> np.ndarray:
    """``nearest_rows`` by cells: the distance of a query to any member of a cell is at least its distance to the
    centre minus the cell's radius R (the triangle inequality, in the points' own space), so the cells whose
    bound exceeds the distance to the nearest centre cannot hold the nearest row. Queries are taken in groups of
    ``group`` with neighbouring nearest centres (``cells.rank``) and each group scored by one product against the
    members of every cell one of them still needs, in ascending row order, then near ties scored exactly as in
    the brute force (``_nearest_scored``); the bounds are widened by a bound on float32's rounding of
    ``|x|^2 - 2 x.y`` so that rounding never prunes the nearest row. A spectral embedding is a surface in k
    dimensions, so a query needs a few cells: with ``MeshBasis.vertex_cells`` 0.32-0.38 of the brute force's time for
    2,000 queries among a course pose's 12,500 vertices, 0.61-0.69 for 1,000 among a generated body's 4,700
    (``bench/dense_searches.py``).
    """
    centres = np.asarray(cells.centres, dtype=np.int64)
    owner = np.asarray(cells.owner, dtype=np.int64)
    C, sq_c = points[centres], sq[centres]
    offset = points - C[owner]
    radius = np.zeros(len(centres), dtype=np.float32)
    np.maximum.at(radius, owner, np.sqrt(np.einsum("ij,ij->i", offset, offset)))
    # |error| of a float32 |x|^2 + |y|^2 - 2 x.y <= ~2 d eps (|x|^2 + |y|^2); its square root bounds the distance's
    slack = 2.0 * np.sqrt(2.0 * points.shape[1] * np.finfo(np.float32).eps * (qq + sq.max()))
    out = np.empty(len(queries), dtype=np.int64)
    for s in range(0, len(queries), block):
        Q = queries[s:s + block]
        dist = Q @ C.T
        dist *= -2.0
        dist += sq_c[None, :]
        dist += qq[s:s + block, None]
        np.maximum(dist, 0.0, out=dist)
        np.sqrt(dist, out=dist)
        nearest = np.argmin(dist, axis=1)
        bound = dist[np.arange(len(Q)), nearest] + slack[s:s + block]
        dist -= radius[None, :]
        needed = dist <= bound[:, None]                                  # (b, c) cells that may hold the nearest
        order = np.argsort(cells.rank[nearest], kind="stable")
        for g in range(0, len(Q), group):
            rows = order[g:g + group]
            members = np.flatnonzero(needed[rows].any(axis=0)[owner])
            out[s + rows] = members[_nearest_scored(Q[rows], points[members], sq[members], score_slack[s + rows])]
    return out


def p2p_from_fmap(C: np.ndarray, Phi_S_rows: np.ndarray, Phi_T_cands: np.ndarray, adjoint: bool = True,
                  cells: RowCells | None = None) -> np.ndarray:
    """Point map of a functional map.

    ``adjoint`` (default, as ZoomOut and pyFM): nearest row of ``Phi_T C^T`` (target deltas pushed to the
    template's coefficients) to each row of ``Phi_S``; otherwise nearest row of ``Phi_T`` to each row of
    ``Phi_S C``. The two agree for an orthogonal C; the adjoint one keeps ZoomOut from drifting to a shrunken,
    non-orthogonal C (seen on the hardest course SCAPE poses).

    Args: C: (k_s, k_t); Phi_S_rows: (r, k_s); Phi_T_cands: (c, k_t); cells: a partition of the candidates
    (``nearest_rows``: the same answer, faster for many candidates). Returns (r,) int index into the candidates.
    """
    if adjoint:
        return nearest_rows(Phi_S_rows, Phi_T_cands @ C.T, cells=cells)
    return nearest_rows(Phi_S_rows @ C, Phi_T_cands, cells=cells)


def chirality_functions(basis: MeshBasis, dist: np.ndarray) -> np.ndarray:
    """Orientation-aware, pose-invariant vertex functions from distance fields.

    For each pair (i, j) of distance fields, s_ij = <n, g_i x g_j> with g the unit face gradients: the signed
    sine of the angle between the directions away from landmarks i and j. It is intrinsic (unchanged by bending)
    and changes sign on the mirror image, so it tells the belly from the back and left from right, which the
    distances alone cannot.

    Args: basis: the mesh; dist: (n, L) distance fields (e.g. geodesic distance to L landmarks), L >= 2.
    Returns: (n, L (L-1) / 2) float in [-1, 1], face values averaged to vertices (area weights).
    """
    from itertools import combinations

    G = face_gradients(basis, dist)                                       # (m,3,L)
    G /= np.maximum(np.linalg.norm(G, axis=1, keepdims=True), 1e-12)
    N, _ = basis.face_frames()
    pairs = list(combinations(range(dist.shape[1]), 2))
    i, j = np.array(pairs).T
    # <n, g_i x g_j> = g_j . (n x g_i): one cross product per field instead of one per pair
    W = np.stack([N[:, 1:2] * G[:, 2] - N[:, 2:3] * G[:, 1], N[:, 2:3] * G[:, 0] - N[:, 0:1] * G[:, 2],
                  N[:, 0:1] * G[:, 1] - N[:, 1:2] * G[:, 0]], axis=1)     # (m,3,L): n x g
    s = np.einsum("mcp,mcp->mp", W[:, :, i], G[:, :, j])                  # (m, P)
    return _face_to_vertex_mean(basis, s)


def _face_to_vertex_mean(basis: MeshBasis, face_values: np.ndarray) -> np.ndarray:
    """Area-weighted mean of face values (m, q) over the faces around each vertex -> (n, q) float."""
    incidence, w = basis.cached("face_to_vertex_mean", lambda: _area_incidence(basis))
    return (incidence @ face_values) / np.maximum(w, 1e-300)[:, None]


def _area_incidence(basis: MeshBasis):
    """Vertex-face incidence weighted by face area, (n, m) sparse csr, and its row sums (n,) float."""
    import scipy.sparse as sp

    A = face_areas(basis.V, basis.F)
    m = len(basis.F)
    incidence = sp.csr_matrix((np.repeat(A, 3), (basis.F.ravel(), np.repeat(np.arange(m), 3))), shape=(basis.n, m))
    w = np.asarray(incidence.sum(axis=1)).ravel()
    w.setflags(write=False)
    return incidence, w
