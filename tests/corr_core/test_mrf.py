"""Tests for corr_core.mrf against brute force on tiny problems (n=4 nodes, L=3 labels: 81 labelings)."""
import itertools

import numpy as np
import pytest

from corr_core.mrf import (DensePairwise, best_of_random_restarts, climb, energy, icm, leading_eigenvalue,
                           random_labels, solve_lh, upper_bound)


def random_symmetric_W(n, L, rng, low=0.0, high=1.0):
    W = rng.uniform(low, high, size=(n, n, L, L))
    W = 0.5 * (W + W.transpose(1, 0, 3, 2))
    W[np.arange(n), np.arange(n)] = 0.0
    return W


def planted_W(n, L, rng, truth, strength=1.0, noise=0.3, shift_invariant=True):
    """Noise plus ``strength`` on the planted pairs: on every (a, b) with b - a == truth_j - truth_i (mod L)
    if shift_invariant (the alignment structure: optimum only up to a global shift), else only on
    (truth_i, truth_j) (an easy problem with a unique planted optimum)."""
    W = noise * rng.uniform(size=(n, n, L, L))
    for i, j in itertools.product(range(n), range(n)):
        if shift_invariant:
            a = np.arange(L)
            W[i, j, a, (a + truth[j] - truth[i]) % L] += strength
        else:
            W[i, j, truth[i], truth[j]] += strength
    W = 0.5 * (W + W.transpose(1, 0, 3, 2))
    W[np.arange(n), np.arange(n)] = 0.0
    return W


def energy_by_definition(W, U, labels):
    n = len(labels)
    e = sum(U[i, labels[i]] for i in range(n))
    e += sum(W[i, j, labels[i], labels[j]] for i in range(n) for j in range(i + 1, n))
    return e


def brute_force(W, U):
    n, L = U.shape
    best, best_e = None, -np.inf
    for lab in itertools.product(range(L), repeat=n):
        e = energy_by_definition(W, U, lab)
        if e > best_e:
            best, best_e = np.array(lab), e
    return best, best_e


def is_local_max(pw, U, labels):
    e0 = energy(pw, U, labels)
    for i in range(len(labels)):
        for a in range(U.shape[1]):
            lab = labels.copy()
            lab[i] = a
            if energy(pw, U, lab) > e0 + 1e-12:
                return False
    return True


def test_dense_matvec_equals_explicit_matrix_product():
    rng = np.random.default_rng(0)
    n, L = 5, 4
    W = random_symmetric_W(n, L, rng, -1.0, 1.0)
    pw = DensePairwise(W)
    M = np.zeros((n * L, n * L))
    for i, a, j, b in itertools.product(range(n), range(L), range(n), range(L)):
        M[i * L + a, j * L + b] = W[i, j, a, b]
    X = rng.normal(size=(n, L))
    np.testing.assert_allclose(pw.matvec(X).ravel(), M @ X.ravel(), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(M, M.T)
    for j, b in [(0, 0), (3, 2), (4, 3)]:
        np.testing.assert_array_equal(pw.column(j, b), M[:, j * L + b].reshape(n, L))


def test_dense_zeroes_diagonal_blocks_and_rejects_asymmetric():
    rng = np.random.default_rng(1)
    W = random_symmetric_W(3, 2, rng)
    W[1, 1] = 5.0
    pw = DensePairwise(W)
    assert np.all(pw.W[1, 1] == 0)
    W2 = random_symmetric_W(3, 2, rng)
    W2[0, 1, 0, 1] += 1.0
    with pytest.raises(ValueError):
        DensePairwise(W2)


def test_energy_matches_definition():
    rng = np.random.default_rng(2)
    n, L = 4, 3
    W = random_symmetric_W(n, L, rng, -1, 1)
    U = rng.normal(size=(n, L))
    pw = DensePairwise(W)
    for lab in itertools.product(range(L), repeat=n):
        assert energy(pw, U, np.array(lab)) == pytest.approx(energy_by_definition(W, U, lab), abs=1e-12)


@pytest.mark.parametrize("seed", range(20))
def test_lh_is_local_max_and_not_worse_than_icm_from_its_start(seed):
    rng = np.random.default_rng(seed)
    n, L = 4, 3
    W = random_symmetric_W(n, L, rng)
    U = rng.uniform(size=(n, L))
    pw = DensePairwise(W)
    res = solve_lh(pw, U)
    _, e_opt = brute_force(W, U)
    assert res.converged
    assert is_local_max(pw, U, res.labels)
    assert res.energy == pytest.approx(energy_by_definition(W, U, res.labels))
    assert res.energy >= res.energy_before_climb - 1e-12
    start = np.argmax(res.relaxed, axis=1)  # argmax of the simplex rows == argmax of the relaxed rows
    assert res.energy >= energy(pw, U, icm(pw, U, start)) - 1e-12
    assert res.energy <= e_opt + 1e-12
    assert res.upper_bound >= e_opt - 1e-12
    # simplex_value is an expectation of E over independent labels, so it cannot exceed the optimum
    assert res.simplex_value <= e_opt + 1e-12


@pytest.mark.parametrize("seed", range(20))
def test_lh_finds_brute_force_optimum_on_planted_problems(seed):
    rng = np.random.default_rng(100 + seed)
    n, L = 4, 3
    truth = rng.integers(0, L, size=n)
    W = planted_W(n, L, rng, truth, shift_invariant=False)
    U = 0.1 * rng.uniform(size=(n, L))
    pw = DensePairwise(W)
    best, e_opt = brute_force(W, U)
    res = solve_lh(pw, U)
    np.testing.assert_array_equal(best, truth)
    assert res.energy == pytest.approx(e_opt, abs=1e-12)
    np.testing.assert_array_equal(res.labels, best)


def test_lh_recovers_planted_labels_up_to_global_shift_larger_problem():
    rng = np.random.default_rng(7)
    n, L = 30, 8
    truth = rng.integers(0, L, size=n)
    pw = DensePairwise(planted_W(n, L, rng, truth, strength=1.0, noise=0.5))
    U = 0.01 * rng.uniform(size=(n, L))
    res = solve_lh(pw, U)
    diffs = (res.labels - truth) % L
    assert np.all(diffs == diffs[0])
    assert res.upper_bound >= res.energy


@pytest.mark.parametrize("seed", range(30))
def test_climbing_never_decreases_energy(seed):
    rng = np.random.default_rng(200 + seed)
    n, L = 6, 4
    W = random_symmetric_W(n, L, rng, -1.0, 1.0)  # also with negative potentials
    U = rng.normal(size=(n, L))
    pw = DensePairwise(W)
    x0 = random_labels(n, L, rng)
    e_prev = energy(pw, U, x0)
    # single sweeps compose into the full climb; check each sweep separately
    x = x0
    for _ in range(20):
        x_next, moves = climb(pw, U, x, max_sweeps=1)
        e_next = energy(pw, U, x_next)
        assert e_next >= e_prev - 1e-12
        if moves == 0:
            break
        assert e_next > e_prev
        x, e_prev = x_next, e_next
    assert is_local_max(pw, U, x)


@pytest.mark.parametrize("seed", range(10))
def test_upper_bound_is_valid_with_negative_potentials(seed):
    rng = np.random.default_rng(300 + seed)
    n, L = 4, 3
    W = random_symmetric_W(n, L, rng, -1.0, 1.0)
    U = rng.normal(size=(n, L))
    pw = DensePairwise(W)
    _, e_opt = brute_force(W, U)
    assert upper_bound(pw, U) >= e_opt - 1e-12
    lam = np.linalg.eigvalsh(pw.as_matrix())[-1]
    assert leading_eigenvalue(pw) == pytest.approx(lam, rel=1e-10, abs=1e-12)


def test_leading_eigenvalue_lanczos_path_matches_dense():
    rng = np.random.default_rng(5)
    n, L = 30, 16  # nL = 480 > 400: Lanczos
    pw = DensePairwise(random_symmetric_W(n, L, rng))
    assert leading_eigenvalue(pw) == pytest.approx(np.linalg.eigvalsh(pw.as_matrix())[-1], rel=1e-8)


def test_best_of_random_restarts_reaches_optimum_with_enough_restarts():
    rng = np.random.default_rng(9)
    n, L = 4, 3
    W = random_symmetric_W(n, L, rng)
    U = rng.uniform(size=(n, L))
    pw = DensePairwise(W)
    _, e_opt = brute_force(W, U)
    labels, e = best_of_random_restarts(pw, U, n_restarts=60, seed=0)
    assert e == pytest.approx(energy(pw, U, labels))
    assert e == pytest.approx(e_opt)
    assert is_local_max(pw, U, labels)
