"""refine_deform (ARAP registration): fan rotations are exact, noise and slides shrink, the true map stays."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from corr_core.correspondence.dense import measures, mesh_basis, refine_deform, refine_map, refine_settle
from corr_core.correspondence.dense.deform import _fan_rotations, _incidence, _Target, arap_operators
from corr_core.geometry.primitives import rotation_about_y


def _error(T, p2p, vertices=None):
    return float(measures.dense_errors(T.V, T.F, {"m": p2p}, np.arange(T.n), vertices=vertices)["m"].mean())


def _mean_edge(T) -> float:
    return float(np.linalg.norm(T.V[T.F[:, 0]] - T.V[T.F[:, 1]], axis=1).mean())


def test_fan_rotations_recover_a_rigid_rotation(pair):
    S, _ = pair
    R_true = rotation_about_y(0.7) @ np.array([[1, 0, 0], [0, np.cos(0.3), -np.sin(0.3)], [0, np.sin(0.3), np.cos(0.3)]])
    edges, weights, _, _ = arap_operators(S.V, S.F)
    unsigned, _ = _incidence(edges, S.n)
    E0 = S.V[edges[:, 0]] - S.V[edges[:, 1]]
    R = _fan_rotations(E0, E0 @ R_true.T, weights, unsigned)
    assert np.allclose(R, R_true, atol=1e-8)
    assert np.allclose(np.linalg.det(R), 1.0)


def test_fan_rotations_are_the_best_rotation_of_every_fan_of_a_bent_mesh(pair):
    """Against the textbook solution (SVD of each fan's weighted covariance, reflections excluded) on a non-rigid
    deformation: every vertex's fan gets its own rotation."""
    S, _ = pair
    edges, weights, _, _ = arap_operators(S.V, S.F)
    unsigned, _ = _incidence(edges, S.n)
    bent = S.V + 0.05 * np.sin(3.0 * S.V[:, [1, 2, 0]]) + 0.02 * np.random.default_rng(0).standard_normal(S.V.shape)
    E0, E1 = S.V[edges[:, 0]] - S.V[edges[:, 1]], bent[edges[:, 0]] - bent[edges[:, 1]]
    R = _fan_rotations(E0, E1, weights, unsigned, squarings=12)
    cov = np.asarray(unsigned @ (weights[:, None, None] * E0[:, :, None] * E1[:, None, :]).reshape(-1, 9)).reshape(-1, 3, 3)
    U, _, Wt = np.linalg.svd(cov)                                        # R = W diag(1, 1, det) U^T
    D = np.tile(np.eye(3), (S.n, 1, 1))
    D[:, 2, 2] = np.sign(np.linalg.det(np.einsum("bji,bkj->bik", Wt, U)))
    expected = np.einsum("bji,bjk,blk->bil", Wt, D, U)
    gap = np.sort(np.linalg.svd(cov, compute_uv=False), axis=1)
    clear = gap[:, 1] - gap[:, 0] > 1e-3 * gap[:, 2]                   # fans with a well-defined best rotation
    assert clear.mean() > 0.9
    assert np.allclose(R[clear], expected[clear], atol=1e-6)


def test_arap_operators_are_a_graph_laplacian_with_nonnegative_weights(pair):
    S, _ = pair
    edges, weights, K, mass = arap_operators(S.V, S.F)
    assert (edges[:, 0] < edges[:, 1]).all() and (weights >= 0).all()
    assert np.allclose(K @ np.ones(S.n), 0.0) and np.isclose(mass.sum(), S.area, rtol=1e-6)


def test_refine_deform_removes_most_of_a_noisy_map(pair):
    """Every image moved to a random target vertex within ~2 edges of the truth: the deformed template is smooth,
    so the noise goes (the nearest-vertex steps cannot tell which of the close vertices is right)."""
    S, T = pair
    rng = np.random.default_rng(0)
    _, near = cKDTree(T.V).query(T.V, k=7)
    noisy = near[np.arange(T.n), rng.integers(1, 7, T.n)]
    before = _error(T, noisy)
    after = _error(T, refine_deform(S, T, noisy))
    assert after < 0.4 * before, (before, after)


def test_refine_deform_pulls_back_a_slid_region(pair):
    """A torso disc (radius 0.12 sqrt(area)) sent 3 edges sideways: its neighbours hold it in place."""
    S, T = pair
    centre = int(np.argmin(np.linalg.norm(S.V - np.array([0.0, 1.15, 0.2]), axis=1)))
    region = np.flatnonzero(S.distances([centre])[0] < 0.12)
    p2p = np.arange(S.n)
    p2p[region] = cKDTree(T.V).query(T.V[region] + np.array([3.0 * _mean_edge(T), 0.0, 0.0]))[1]
    before = _error(T, p2p, region)
    after = _error(T, refine_deform(S, T, p2p), region)
    assert after < 0.6 * before, (before, after)


def test_refine_deform_keeps_the_true_map(pair):
    S, T = pair
    kept = refine_deform(S, T, np.arange(S.n))
    assert _error(T, kept) < 0.25 * _mean_edge(T) / T.scale


def test_refine_settle_removes_what_the_anchors_of_refine_deform_leave(pair):
    """From a noisy map, ``refine_deform`` keeps a little of the noise (its anchors are the noisy images);
    ``refine_settle`` (no anchors: ARAP against the surface alone) takes it to a quarter or less, keeps the true
    map, and is the refinement step "settle" (on request, not a default step)."""
    from corr_core.correspondence.dense import DEFAULT_REFINE

    S, T = pair
    rng = np.random.default_rng(0)
    _, near = cKDTree(T.V).query(T.V, k=7)
    deformed = refine_deform(S, T, near[np.arange(T.n), rng.integers(1, 7, T.n)])
    settled = refine_settle(S, T, deformed)
    assert _error(T, settled) < 0.25 * _error(T, deformed), (_error(T, deformed), _error(T, settled))
    assert _error(T, refine_settle(S, T, np.arange(S.n))) < 0.25 * _mean_edge(T) / T.scale
    assert np.array_equal(refine_map(S, T, deformed, "settle"), settled) and "settle" not in DEFAULT_REFINE


def test_refine_deform_is_the_deform_step_and_checks_its_arguments(pair):
    S, T = pair
    p2p = np.arange(S.n)[::-1].copy() % T.n
    assert np.array_equal(refine_map(S, T, p2p, "deform", {"deform": {"iterations": 2}}),
                          refine_deform(S, T, p2p, iterations=2))
    for bad in ({"stiffness": 0.0}, {"iterations": 0}, {"anchor_weight": 1.5}):
        with pytest.raises(ValueError, match="refine_deform"):
            refine_deform(S, T, p2p, **bad)


def test_data_term_pulls_onto_the_tangent_plane_of_a_compatible_target_vertex():
    """The ARAP data goal on a flat target (z = 0, normals +z): a vertex whose image is an outlier is pulled onto
    the target's tangent plane (point-to-plane, not to the vertex), one facing the other way is not pulled at
    all, and an inlier gets ``anchor_weight`` of its image and the rest of the plane point."""
    xs, ys = np.meshgrid(np.arange(6.0), np.arange(6.0))
    V = np.c_[xs.ravel(), ys.ravel(), np.zeros(36)]
    corner = (np.arange(5)[:, None] * 6 + np.arange(5)[None, :]).ravel()           # lower-left of each square
    quads = np.c_[corner, corner + 1, corner + 7, corner + 6]
    F = np.r_[quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]                  # counter-clockwise seen from +z
    target = _Target(mesh_basis(V, F, k=4, n_samples=4))
    assert np.allclose(target.normals, [0.0, 0.0, 1.0])
    rng = np.random.default_rng(0)
    X = np.c_[rng.uniform(1.0, 4.0, (9, 2)), rng.uniform(0.1, 0.4, 9)]      # above the interior of the grid
    normals = np.tile([0.0, 0.0, 1.0], (9, 1))
    normals[2] = [0.0, 0.0, -1.0]
    anchors = X.copy()
    anchors[:3] += [0.0, 0.0, 5.0]               # three outliers, six exact images: median distance 0
    goal = target.data_goal(X, normals, anchors, anchor_weight=0.5, outlier=3.0, normal_cos=0.5)
    np.testing.assert_allclose(goal[:2], X[:2] * [1.0, 1.0, 0.0], atol=1e-12)   # onto the plane, in place
    np.testing.assert_allclose(goal[2], X[2])                                 # facing away: no pull
    np.testing.assert_allclose(goal[3:], 0.5 * X[3:] + 0.5 * X[3:] * [1.0, 1.0, 0.0], atol=1e-12)


def test_pinned_solve_is_the_constrained_minimizer(pair):
    """``TemplateARAP.pinned_solve`` gives the minimizer of the registration's quadratic energy under x[pins] = at:
    the solution of the KKT system, and the pinned entries exactly."""
    import scipy.sparse as sp

    from corr_core.correspondence.dense.deform import TemplateARAP

    S, _ = pair
    arap = TemplateARAP(S.V, S.F, 0.03, S.area)
    _, _, K, _ = arap_operators(S.V, S.F)
    A = (K + sp.diags(arap.lam)).toarray()
    pins = np.array([5, 40, 123])
    rhs = np.random.default_rng(1).standard_normal(S.n)
    at = np.array([0.1, -0.2, 0.3])
    x = arap.pinned_solve(pins)(rhs, at)
    U = np.zeros((S.n, len(pins)))
    U[pins, np.arange(len(pins))] = 1.0
    kkt = np.block([[A, U], [U.T, np.zeros((len(pins), len(pins)))]])
    want = np.linalg.solve(kkt, np.r_[rhs, at])[:S.n]
    assert np.allclose(x, want, atol=1e-8)
    assert np.allclose(x[pins], at, atol=1e-10)


def test_refine_deform_holds_given_points_where_they_are_given(pair):
    """With ``points`` the map sends each given template point to its given target point even when that is a few
    edges off the truth (without them the registration pulls them back), and the first pair of a repeated
    template id counts."""
    S, T = pair
    truth = np.arange(S.n)
    nbrs = cKDTree(T.V).query(T.V[[10, 200, 350, 500]], k=4)[1][:, 3]     # a vertex a few edges off the truth
    given = (np.array([10, 200, 350, 500, 10]), np.r_[nbrs, 77])
    free = refine_deform(S, T, truth)
    held = refine_deform(S, T, truth, points=given)
    assert not np.array_equal(free[given[0][:4]], nbrs)
    assert np.array_equal(held[given[0][:4]], nbrs)
    assert _error(T, held) < 0.05                                  # the rest of the map stays near the truth
    assert np.array_equal(refine_settle(S, T, truth, points=given)[given[0][:4]], nbrs)


def test_the_registration_holds_pinned_vertices_at_their_positions(pair):
    """``TemplateARAP.register`` with pins: those vertices end exactly at the given positions (not merely near
    the target), the others move as the registration moves them."""
    from corr_core.correspondence.dense.deform import TemplateARAP

    S, T = pair
    arap = TemplateARAP(S.V, S.F, 0.03, S.area)
    ids = np.array([10, 200, 350])
    at = T.V[ids] + np.array([0.01, -0.01, 0.005])                     # off the target surface on purpose
    X = arap.register(_Target(T), T.V.copy(), 3, 0.5, 3.0, 0.5, pins=(ids, at))
    assert np.allclose(X[ids], at, atol=1e-10)
    free = arap.register(_Target(T), T.V.copy(), 3, 0.5, 3.0, 0.5)
    assert not np.allclose(free[ids], at, atol=1e-4)


def test_every_refinement_step_keeps_given_points(pair):
    """A step that takes no points (spectral, extrinsic) still leaves the given points where they are given."""
    S, T = pair
    truth = np.arange(S.n)
    given = (np.array([10, 200]), np.array([11, 201]))
    for plan in ("spectral", "extrinsic", "extrinsic+spectral+deform"):
        refined = refine_map(S, T, truth, plan, points=given)
        assert np.array_equal(refined[given[0]], given[1]), plan
    repeated = (np.array([10, 200, 10]), np.array([11, 201, 12]))          # the first pair of a template id counts
    for plan in ("spectral", "deform"):
        assert np.array_equal(refine_map(S, T, truth, plan, points=repeated)[[10, 200]], [11, 201]), plan
    with pytest.raises(ValueError, match="unknown option"):
        refine_map(S, T, truth, "deform", {"deform": {"points": given}})
