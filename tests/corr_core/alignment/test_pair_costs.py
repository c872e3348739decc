"""Tests for corr_core.alignment.pair_costs: C_ij(theta) vs its definition and the naive loop, mirror, shifts,
auto sigma."""
import itertools

import numpy as np
import pytest

from corr_core.alignment.pair_costs import auto_sigma, mirror_pair_costs, pair_costs, pair_costs_naive, shift_costs


def features(N, V, D, seed):
    return np.random.default_rng(seed).normal(size=(N, V, D)).astype(np.float32)


def test_pair_costs_match_definition_and_naive():
    F = features(4, 6, 5, 0)
    C = pair_costs(F)
    assert C.dtype == np.float32 and C.shape == (4, 4, 6)
    Fd = F.astype(np.float64)
    for i, j, theta in itertools.product(range(4), range(4), range(6)):
        ref = sum(np.sum((Fd[i, v] - Fd[j, (v + theta) % 6]) ** 2) for v in range(6))
        assert C[i, j, theta] == pytest.approx(ref, rel=1e-4, abs=1e-3)
    np.testing.assert_allclose(C, pair_costs_naive(F), rtol=1e-4, atol=1e-3)


@pytest.mark.parametrize("V", [5, 8, 16])
def test_pair_costs_rectangular_and_mirror(V):
    FA, FB = features(3, V, 7, 1), features(5, V, 7, 2)
    C_ab = pair_costs(FA, FB)
    assert C_ab.shape == (3, 5, V)
    np.testing.assert_allclose(C_ab, pair_costs_naive(FA, FB), rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(mirror_pair_costs(C_ab), pair_costs(FB, FA), rtol=1e-4, atol=1e-3)


def test_pair_costs_zero_at_planted_rotation():
    """Shape j = shape i rotated by s steps: F_j[(v+s)%V] == F_i[v], so C_ij(s) == 0 and only there."""
    V, s = 16, 5
    Fi = features(1, V, 20, 3)[0]
    Fj = np.roll(Fi, s, axis=0)
    np.testing.assert_array_equal(Fj[(np.arange(V) + s) % V], Fi)
    c = pair_costs(Fi[None], Fj[None])[0, 0]
    assert c[s] == pytest.approx(0.0, abs=1e-3)
    assert np.argmin(c) == s and np.sort(c)[1] > 10.0


def test_auto_sigma_is_median_of_best_pair_costs():
    rng = np.random.default_rng(4)
    C = rng.uniform(1, 10, size=(5, 5, 4))
    C = 0.5 * (C + mirror_pair_costs(C))
    best = [C[i, j].min() for i in range(5) for j in range(i + 1, 5)]
    assert auto_sigma(C) == pytest.approx(np.median(best))


def test_shift_costs_equals_costs_of_shifted_views():
    """Rolling shape i's views by s_i (as if rotated by +s_i steps) is the same as shift_costs on C."""
    N, V = 4, 8
    F = features(N, V, 6, 5)
    shifts = np.array([0, 3, 7, 1])
    rotated = np.stack([np.roll(F[i], shifts[i], axis=0) for i in range(N)])
    np.testing.assert_allclose(shift_costs(pair_costs(F), shifts), pair_costs(rotated), rtol=1e-4, atol=1e-3)
    np.testing.assert_array_equal(shift_costs(pair_costs(F), np.zeros(N, dtype=int)), pair_costs(F))
