"""Candidate graph (corr_core.alignment.candidates) and the solvers on its sparse costs
(corr_core.alignment.graph_costs): invariant descriptors, a connected deterministic graph, and the same answers
as the dense complete-graph path on small planted data."""
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from corr_core.alignment import candidates, continuous, graph_costs, measures, solvers
from corr_core.alignment.azimuth import agreement_up_to_offset
from corr_core.alignment.circulant import CirculantPairwise, neighbor_graph
from corr_core.alignment.pair_costs import mirror_pair_costs, pair_costs, pair_costs_listed
from corr_core.alignment.symmetry import symmetry_periods
from tests.corr_core.alignment.test_symmetry import collection


def planted_features(N=40, V=8, D=20, noise=0.3, seed=0):
    """Features (N, V, D) of noisy copies of one random shape, shape i's views rolled by offsets[i]."""
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(V, D))
    offsets = rng.integers(0, V, size=N)
    F = np.stack([np.roll(base + noise * rng.normal(size=(V, D)), o, axis=0) for o in offsets])
    return F.astype(np.float32), offsets


def mirrored_costs(F):
    """Dense C (N, N, V) whose lower triangle is exactly the mirror of the upper one (as the engine assembles
    pair tiles), so that the dense and the graph operators see the same numbers."""
    C = pair_costs(F)
    i, j = np.tril_indices(len(F), -1)
    C[i, j] = mirror_pair_costs(C[j, i][:, None])[0]  # (P, 1, V) -> (1, P, V)
    return C


# ---- descriptor --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("dim", [0, 16])
def test_descriptor_is_invariant_under_cyclic_view_shifts(dim):
    rng = np.random.default_rng(1)
    F = rng.normal(size=(16, 50)).astype(np.float32)
    d = candidates.rotation_invariant_descriptor(F, dim=dim)
    for s in (1, 5, 8, 15):
        np.testing.assert_allclose(candidates.rotation_invariant_descriptor(np.roll(F, s, axis=0), dim=dim), d,
                                   rtol=1e-5, atol=1e-5)
    # it is not blind: another view order (not a rotation) or another shape changes it
    assert not np.allclose(candidates.rotation_invariant_descriptor(F[rng.permutation(16)], dim=dim), d, atol=1e-3)
    assert not np.allclose(candidates.rotation_invariant_descriptor(F + 0.3, dim=dim), d, atol=1e-3)


def test_full_descriptor_distance_is_a_lower_bound_of_the_best_rotation_cost():
    F, _ = planted_features(N=12, V=16, noise=1.0)
    M = candidates.rotation_invariant_descriptor(F, dim=0)
    dist2 = ((M[:, None] - M[None]) ** 2).sum(axis=2)
    best = pair_costs(F).min(axis=2)
    assert np.all(dist2 <= best * (1 + 1e-4) + 1e-3)
    assert np.median(dist2[np.triu_indices(12, 1)] / best[np.triu_indices(12, 1)]) > 0.3  # and not a loose one


def test_descriptor_batch_and_projection_are_deterministic():
    F, _ = planted_features(N=5)
    batch = candidates.rotation_invariant_descriptor(F, dim=8, seed=3)
    assert batch.shape == (5, 8) and batch.dtype == np.float32
    np.testing.assert_array_equal(batch, candidates.rotation_invariant_descriptor(F, dim=8, seed=3))
    np.testing.assert_allclose(batch[2], candidates.rotation_invariant_descriptor(F[2], dim=8, seed=3), rtol=1e-5)
    assert not np.allclose(batch, candidates.rotation_invariant_descriptor(F, dim=8, seed=4))
    with pytest.raises(ValueError, match=r"\(V, D\)"):
        candidates.rotation_invariant_descriptor(np.zeros(5))


# ---- candidate graph ---------------------------------------------------------------------------------------

def _n_components(N, pairs):
    A = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(N, N))
    return connected_components(A, directed=False)[0]


def test_candidate_graph_has_the_k_nearest_random_pairs_and_is_deterministic():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(200, 6))
    pairs, kind = candidates.candidate_pairs(X, k=5, n_random=2, seed=7)
    again, kind2 = candidates.candidate_pairs(X, k=5, n_random=2, seed=7)
    np.testing.assert_array_equal(pairs, again)
    np.testing.assert_array_equal(kind, kind2)
    assert np.all(pairs[:, 0] <= pairs[:, 1]) and len(np.unique(pairs, axis=0)) == len(pairs)
    have = set(map(tuple, pairs.tolist()))
    dist = np.linalg.norm(X[:, None] - X[None], axis=2)
    np.fill_diagonal(dist, np.inf)
    for i in range(200):
        for j in np.argsort(dist[i])[:5]:
            assert (min(i, j), max(i, j)) in have
    assert (kind == candidates.PAIR_KINDS["self"]).sum() == 200
    assert 380 <= (kind == candidates.PAIR_KINDS["random"]).sum() <= 400
    off = pairs[pairs[:, 0] != pairs[:, 1]]
    assert len(off) < 200 * 7 and _n_components(200, off) == 1
    other, _ = candidates.candidate_pairs(X, k=5, n_random=2, seed=8)
    assert not np.array_equal(other, pairs)


def test_candidate_graph_is_connected_even_when_the_nearest_shapes_are_not():
    rng = np.random.default_rng(0)
    X = np.concatenate([rng.normal(size=(30, 3)), 100 + rng.normal(size=(30, 3)), -100 + rng.normal(size=(30, 3))])
    knn_only = candidates.nearest_pairs(X, 4)
    assert _n_components(90, knn_only) == 3
    pairs, kind = candidates.candidate_pairs(X, k=4, n_random=0, self_pairs=False)
    assert _n_components(90, pairs) == 1
    assert (kind == candidates.PAIR_KINDS["bridge"]).sum() == 2


def test_bad_descriptors_name_the_shape():
    X = np.zeros((4, 3))
    X[2, 1] = np.nan
    with pytest.raises(ValueError, match="shape #2"):
        candidates.candidate_pairs(X)


# ---- pair costs of listed pairs ----------------------------------------------------------------------------

@pytest.mark.parametrize("n_pairs", [6, 40])  # sparse (gathered) and dense-block paths
def test_listed_pair_costs_equal_the_tile_values(n_pairs):
    F, _ = planted_features(N=14, V=8)
    A, B = F[:8], F[5:]
    rng = np.random.default_rng(2)
    pairs = np.stack([rng.integers(0, 8, n_pairs), rng.integers(0, 9, n_pairs)], axis=1)
    got = pair_costs_listed(A, B, pairs)
    assert got.shape == (n_pairs, 8) and got.dtype == np.float32
    np.testing.assert_allclose(got, pair_costs(A, B)[pairs[:, 0], pairs[:, 1]], rtol=1e-5, atol=1e-4)
    with pytest.raises(ValueError, match="outside"):
        pair_costs_listed(A, B, [[0, 9]])


# ---- the solvers on graph costs ----------------------------------------------------------------------------

@pytest.mark.parametrize("solver", solvers.SOLVERS)
def test_sparse_solve_on_all_pairs_equals_the_complete_graph_solve(solver):
    F, offsets = planted_features()
    C = mirrored_costs(F)
    dense = solvers.solve_alignment(C, solver=solver)
    sparse = solvers.solve_alignment(graph_costs.from_dense(C), solver=solver)
    np.testing.assert_array_equal(sparse["labels"], dense["labels"])
    assert agreement_up_to_offset(sparse["labels"], offsets, 8)[0] == 1.0
    assert sparse["sigma"] == dense["sigma"]
    assert sparse["energy"] == pytest.approx(dense["energy"], rel=1e-9)
    np.testing.assert_allclose(sparse["angles_deg"], dense["angles_deg"], atol=1e-6)
    assert sparse["pairs_computed"] == 40 * 39 // 2 and sparse["graph"] == "candidates"


@pytest.mark.parametrize("solver", solvers.SOLVERS)
def test_sparse_solve_on_a_knn_graph_equals_the_knn_solve(solver):
    F, _ = planted_features(N=40)
    C = mirrored_costs(F)
    neighbors = solvers.knn_neighbors(C, 4)
    indptr, indices = neighbor_graph(40, neighbors)
    rows = np.repeat(np.arange(40), np.diff(indptr))
    gc = graph_costs.from_dense(C, np.stack([rows, indices], axis=1))
    sigma = solvers.choose_sigma(C)
    dense_op, graph_op = CirculantPairwise(C, sigma, neighbors), gc.operator(sigma)
    np.testing.assert_array_equal(graph_op.indptr, dense_op.indptr)
    np.testing.assert_array_equal(graph_op.K_edges, dense_op.K_edges)
    np.testing.assert_array_equal(solvers.solve_labels(gc, solver, sigma, 0)["labels"],
                                  solvers.solve_labels(C, solver, sigma, 0, knn=4)["labels"])


@pytest.fixture
def planted_graph():
    """Builder of a candidate graph on planted shapes: ``planted_graph(N, k, n_random)`` ->
    {"offsets": (N,) int, "C": (N, N, 8) dense costs, "pairs": (P, 2) int, "kind": (P,) int, "gc": GraphCosts of
    those pairs with the random ones marked as the sample} (planted_features(N), k neighbours, n_random random
    pairs per shape)."""
    def build(N: int, k: int, n_random: int) -> dict:
        F, offsets = planted_features(N=N)
        C = mirrored_costs(F)
        pairs, kind = candidates.candidate_pairs(candidates.rotation_invariant_descriptor(F, dim=8), k=k,
                                                 n_random=n_random, self_pairs=False)
        gc = graph_costs.from_dense(C, pairs, np.isin(kind, candidates.SAMPLE_KINDS))
        return {"offsets": offsets, "C": C, "pairs": pairs, "kind": kind, "gc": gc}
    return build


def test_graph_sigma_is_the_median_of_the_random_sample(planted_graph):
    graph = planted_graph(N=60, k=3, n_random=2)  # 120 random pairs >= SIGMA_SAMPLE_MIN
    C, pairs, kind = graph["C"], graph["pairs"], graph["kind"]
    best = C.min(axis=2)[pairs[:, 0], pairs[:, 1]]
    assert graph["gc"].auto_sigma() == pytest.approx(np.median(best[kind == candidates.PAIR_KINDS["random"]]))
    assert graph_costs.from_dense(C, pairs).auto_sigma() == pytest.approx(np.median(best))


def test_symmetric_shapes_on_a_graph_are_placed_like_on_the_complete_graph():
    orders = np.array([1] * 10 + [2] * 6 + [4] * 6 + [0] * 4)
    F, offsets = collection(list(orders), noise=0.5, seed=2)
    C = mirrored_costs(F)
    dense = solvers.solve_alignment(C, solver="spectral")
    sparse = solvers.solve_alignment(graph_costs.from_dense(C), solver="spectral")
    np.testing.assert_array_equal(sparse["symmetry_order"], orders)
    np.testing.assert_array_equal(sparse["labels"], dense["labels"])
    assert measures.agreement_modulo(sparse["labels"], offsets, 16, symmetry_periods(orders, 16)) == 1.0


def test_graph_refinement_equals_the_dense_refinement_on_all_pairs():
    F, _ = planted_features(N=30)
    C = mirrored_costs(F)
    labels = solvers.solve_alignment(C, solver="spectral")["labels"]
    gc = graph_costs.from_dense(C)
    np.testing.assert_allclose(continuous.refine_labels_graph(30, gc.rows, gc.cols, gc.costs, labels, 5.0),
                               continuous.refine_labels(C, labels, 5.0), atol=1e-8)


def test_graph_costs_from_engine_pairs_mark_the_sample_and_self_costs():
    F, _ = planted_features(N=30)
    C = mirrored_costs(F)
    X = candidates.rotation_invariant_descriptor(F, dim=8)
    pairs, kind = candidates.candidate_pairs(X, k=3, n_random=1, self_pairs=False)
    names = [f"s{i:02d}" for i in range(30)]
    graph = {"names": names[::-1], "pairs": 29 - pairs, "kind": kind, "self_costs": C[np.arange(30), np.arange(30)][::-1]}
    gc = graph_costs.from_candidates(names, pairs, C[pairs[:, 0], pairs[:, 1]], graph)
    np.testing.assert_array_equal(gc.self_costs, C[np.arange(30), np.arange(30)])
    assert gc.sample.sum() == (kind == candidates.PAIR_KINDS["random"]).sum()
    np.testing.assert_array_equal(gc.pair_cost(int(pairs[0, 1]), int(pairs[0, 0])),
                                  C[pairs[0, 1], pairs[0, 0]])


def test_evaluate_on_graph_costs_reports_the_pairs_computed(planted_graph):
    graph = planted_graph(N=40, k=4, n_random=1)
    gc, pairs, offsets = graph["gc"], graph["pairs"], graph["offsets"]
    sol = {"names": [str(i) for i in range(40)], **solvers.solve_alignment(gc, solver="spectral")}
    truth = {str(i): int(o) for i, o in enumerate(offsets)}
    m = measures.evaluate_alignment(gc, sol, truth, seeds=[0, 1], restarts=1, compare_solvers=True, icm_starts=1)
    assert m["pairs_computed"] == len(pairs) == gc.n_pairs and m["pairs_total"] == 780
    assert m["pairs_fraction"] == pytest.approx(len(pairs) / 780)
    assert m["ground_truth"]["exact"] == 1.0 and m["equivariance"] == 1.0
    q = m["solver_quality"]
    assert q["upper_bound"] >= q["energy"] >= q["random_labeling"]
    with pytest.raises(ValueError, match="knn"):
        solvers.solve_alignment(gc, knn=3)
