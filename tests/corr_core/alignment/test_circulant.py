"""Tests for corr_core.alignment.circulant: the circulant MRF operator (dense and kNN-sparse) vs the dense one."""
import itertools

import numpy as np
import pytest

from corr_core.alignment.circulant import CirculantPairwise, dense_pairwise
from corr_core.alignment.pair_costs import auto_sigma, mirror_pair_costs, nearest_shapes, pair_costs
from corr_core.alignment.solvers import uniform_unary
from corr_core.mrf import DensePairwise, energy, solve_lh


def features(N, V, D, seed):
    return np.random.default_rng(seed).normal(size=(N, V, D)).astype(np.float32)


@pytest.mark.parametrize("use_neighbors", [False, True])
def test_circulant_matches_dense_operator(use_neighbors):
    F = features(7, 8, 6, 5)
    C = pair_costs(F)
    sigma = auto_sigma(C)
    nb = nearest_shapes(C, 2) if use_neighbors else None
    circ, dense = CirculantPairwise(C, sigma, nb), dense_pairwise(C, sigma, nb)
    X = np.random.default_rng(6).normal(size=(7, 8))
    np.testing.assert_allclose(circ.matvec(X), dense.matvec(X), rtol=1e-10, atol=1e-12)
    for j, b in itertools.product(range(7), range(8)):
        np.testing.assert_allclose(circ.column(j, b), dense.column(j, b), atol=1e-14)
    np.testing.assert_allclose(circ.block_max(), dense.block_max())
    # the dense operator is the definition W[i,j,a,b] = exp(-C_ij(b-a)/sigma) (C is mirror-symmetric here)
    i, j, a, b = 1, 4, 6, 3
    Csym = 0.5 * (C.astype(np.float64) + mirror_pair_costs(C.astype(np.float64)))
    expected = np.exp(-Csym[i, j, (b - a) % 8] / sigma)
    if use_neighbors and not (j in nb[i] or i in nb[j]):
        expected = 0.0
    assert dense.W[i, j, a, b] == pytest.approx(expected)


def test_neighbor_graph_is_symmetrized_and_restricts_pairs():
    F = features(6, 4, 3, 7)
    C = pair_costs(F)
    nb = nearest_shapes(C, 1)
    best = C.min(axis=2).astype(float)
    np.fill_diagonal(best, np.inf)
    np.testing.assert_array_equal(nb[:, 0], np.argmin(best, axis=1))
    K = CirculantPairwise(C, 1.0, nb).K
    edges = {(i, int(nb[i, 0])) for i in range(6)}
    for i, j in itertools.product(range(6), range(6)):
        on = (i, j) in edges or (j, i) in edges
        assert (K[i, j].max() > 0) == on


def test_lh_on_circulant_recovers_planted_rotations_and_energy_agrees_with_dense():
    rng = np.random.default_rng(8)
    N, V, D = 12, 16, 30
    base = rng.normal(size=(V, D))
    offsets = rng.integers(0, V, size=N)
    F = np.stack([np.roll(base + 0.2 * rng.normal(size=(V, D)), o, axis=0) for o in offsets])
    C = pair_costs(F)
    sigma = auto_sigma(C)
    U = uniform_unary(N, V, seed=0)
    res = solve_lh(CirculantPairwise(C, sigma), U)
    d = (res.labels - offsets) % V
    assert np.all(d == d[0])
    assert energy(dense_pairwise(C, sigma), U, res.labels) == pytest.approx(res.energy, rel=1e-10)
    assert res.upper_bound >= res.energy


# --- memory-lean storage and the sparse kNN operator ---------------------------------------------------------

def _graph_mask(N, nb):
    mask = np.zeros((N, N), dtype=bool)
    for i in range(N):
        for j in nb[i]:
            mask[i, j] = mask[j, i] = True
    np.fill_diagonal(mask, False)
    return mask


def test_neighbor_graph_csr_matches_brute_force_union():
    from corr_core.alignment.circulant import neighbor_graph
    C = pair_costs(features(9, 6, 4, 12))
    nb = nearest_shapes(C, 3)
    indptr, indices = neighbor_graph(9, nb)
    mask = _graph_mask(9, nb)
    for i in range(9):
        row = indices[indptr[i]:indptr[i + 1]]
        np.testing.assert_array_equal(row, np.flatnonzero(mask[i]))
    assert indices.size == mask.sum() <= 2 * 9 * 3


@pytest.mark.parametrize("k", [1, 3])
def test_sparse_operator_equals_dense_operator_restricted_to_knn_graph(k):
    """The kNN operator (CSR storage) is the complete-graph circulant operator with every pair off the graph
    zeroed: same matvec, columns, block maxima and harmonic, by brute force over all (j, b)."""
    N, V = 11, 8
    C = pair_costs(features(N, V, 5, 13))
    sigma = auto_sigma(C)
    nb = nearest_shapes(C, k)
    sparse = CirculantPairwise(C, sigma, nb)
    full = CirculantPairwise(C, sigma)
    assert sparse.sparse and not full.sparse
    restricted = CirculantPairwise.from_kernel(full.K * _graph_mask(N, nb)[:, :, None])
    X = np.random.default_rng(14).normal(size=(N, V))
    np.testing.assert_allclose(sparse.matvec(X), restricted.matvec(X), rtol=1e-12, atol=1e-14)
    for j, b in itertools.product(range(N), range(V)):
        np.testing.assert_array_equal(sparse.column(j, b), restricted.column(j, b))
    np.testing.assert_array_equal(sparse.block_max(), restricted.block_max())
    np.testing.assert_allclose(np.asarray(sparse.harmonic(h=1).todense()), restricted.harmonic(h=1), atol=1e-13)
    # memory: only the graph's edges are stored (E x V float32), never N x N x V
    E = _graph_mask(N, nb).sum()
    assert sparse.K_edges.shape == (E, V) and sparse.K_edges.dtype == np.float32
    U = uniform_unary(N, V, seed=1)
    labels = np.random.default_rng(2).integers(0, V, N)
    assert energy(sparse, U, labels) == pytest.approx(energy(dense_pairwise(C, sigma, nb), U, labels), rel=1e-12)


def test_dense_kernel_is_float32_and_exactly_symmetric():
    N, V = 6, 16
    C = pair_costs(features(N, V, 7, 15))
    op = CirculantPairwise(C, auto_sigma(C))
    K = op.K
    assert K.dtype == np.float32 and op.nbytes == 4 * N * N * V
    minus = (-np.arange(V)) % V
    np.testing.assert_array_equal(K.transpose(1, 0, 2)[:, :, minus], K)  # bitwise: W[i,j,a,b] == W[j,i,b,a]
    np.testing.assert_array_equal(K[np.arange(N), np.arange(N)], 0.0)
    # the float32 kernel is the float64 definition rounded
    Csym = 0.5 * (C.astype(np.float64) + mirror_pair_costs(C.astype(np.float64)))
    ref = np.exp(-Csym / op.sigma)
    ref[np.arange(N), np.arange(N)] = 0.0
    np.testing.assert_allclose(K, ref, rtol=1e-6, atol=1e-30)


def test_blocked_matvec_equals_single_gemm(monkeypatch):
    """Row-blocked float64 accumulation over a float32 kernel == one float64 product of the upcast kernel."""
    import corr_core.alignment.circulant as circ
    N, V = 13, 8
    C = pair_costs(features(N, V, 5, 16))
    op = CirculantPairwise(C, auto_sigma(C))
    X = np.random.default_rng(3).normal(size=(N, V))
    ref = CirculantPairwise.from_kernel(op.K.astype(np.float64)).matvec(X)
    monkeypatch.setattr(circ, "_rows_per_block", lambda N, V, budget_bytes=0: 3)
    np.testing.assert_allclose(op.matvec(X), ref, rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(CirculantPairwise(C, op.sigma).K, op.K)  # kernel built in 3-row blocks too
