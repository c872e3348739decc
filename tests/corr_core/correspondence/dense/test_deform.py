"""refine_deform (ARAP registration): fan rotations are exact, noise and slides shrink, the true map stays."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from corr_core.correspondence.dense import measures, refine_deform, refine_map
from corr_core.correspondence.dense.deform import _fan_rotations, _incidence, arap_operators
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


def test_refine_deform_is_the_deform_step_and_checks_its_arguments(pair):
    S, T = pair
    p2p = np.arange(S.n)[::-1].copy() % T.n
    assert np.array_equal(refine_map(S, T, p2p, "deform", {"deform": {"iterations": 2}}),
                          refine_deform(S, T, p2p, iterations=2))
    for bad in ({"stiffness": 0.0}, {"iterations": 0}, {"anchor_weight": 1.5}):
        with pytest.raises(ValueError, match="refine_deform"):
            refine_deform(S, T, p2p, **bad)
