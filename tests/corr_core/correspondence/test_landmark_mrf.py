"""Geodesic-consistency landmark MRF: synthetic known permutations, descriptor unaries."""

import numpy as np
import pytest

from corr_core.correspondence.landmark_mrf import consistency_pairwise, descriptor_unary, match_landmarks_mrf
from tests.helpers import normalized_distances



def test_pairwise_weights_formula_and_symmetry():
    rng = np.random.default_rng(0)
    dT, dS = normalized_distances(rng.normal(size=(4, 3))), normalized_distances(rng.normal(size=(5, 3)))
    W = consistency_pairwise(dT, dS, sigma=0.05)
    assert W.shape == (4, 4, 5, 5)
    np.testing.assert_allclose(W, W.transpose(1, 0, 3, 2))
    assert W[0, 1, 2, 3] == pytest.approx(np.exp(-(dT[0, 1] - dS[2, 3]) ** 2 / 0.1))
    assert np.all(W[:, :, np.arange(5), np.arange(5)] == 0)  # shared label: no gain
    assert np.all(W[np.arange(4), np.arange(4)] == 0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recovers_random_permutation_of_asymmetric_points(seed):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(12, 3)) * [3.0, 1.5, 0.7]
    perm = rng.permutation(12)  # test landmark a is template landmark perm[a]
    dT = normalized_distances(X)
    dS = dT[np.ix_(perm, perm)]
    labels = match_landmarks_mrf(dT, dS, sigma=0.05)
    np.testing.assert_array_equal(perm[labels], np.arange(12))


def test_more_labels_than_nodes_and_one_to_one():
    rng = np.random.default_rng(4)
    X = rng.normal(size=(10, 3))
    dS = normalized_distances(X)
    nodes = np.array([7, 2, 5, 0])
    dT = dS[np.ix_(nodes, nodes)] * 1.0
    labels = match_landmarks_mrf(dT, dS, sigma=0.01)
    assert len(set(labels.tolist())) == 4
    np.testing.assert_array_equal(labels, nodes)


def test_descriptor_unary_breaks_a_tie():
    # a square: every rotation/reflection is equally consistent; the unary selects one
    X = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    d = normalized_distances(X)
    target = np.array([2, 3, 0, 1])
    cost = np.ones((4, 4))
    cost[np.arange(4), target] = 0.0
    np.testing.assert_array_equal(match_landmarks_mrf(d, d, unary=descriptor_unary(cost, weight=0.5)), target)
