"""Solver dispatch of the alignment MRF: sigma choice, kNN graph, unary terms, the three solvers."""
import numpy as np
import pytest

from corr_core import mrf
from corr_core.alignment.azimuth import agreement_up_to_offset
from corr_core.alignment.circulant import CirculantPairwise
from corr_core.alignment.pair_costs import auto_sigma, nearest_shapes
from corr_core.alignment.solvers import (SOLVERS, choose_sigma, knn_neighbors, solve_alignment, solve_labels,
                                         uniform_unary)
from tests.helpers import planted_pair_costs


def test_uniform_unary_is_seeded_and_in_unit_interval():
    U = uniform_unary(10, 16, seed=3)
    assert U.shape == (10, 16) and U.min() >= 0 and U.max() < 1
    np.testing.assert_array_equal(U, uniform_unary(10, 16, seed=3))
    assert not np.array_equal(U, uniform_unary(10, 16, seed=4))


def test_choose_sigma_auto_or_given_times_scale():
    C, _ = planted_pair_costs()
    assert choose_sigma(C) == pytest.approx(auto_sigma(C))
    assert choose_sigma(C, "auto", sigma_scale=2.0) == pytest.approx(2 * auto_sigma(C))
    assert choose_sigma(C, None, sigma_scale=0.5) == pytest.approx(0.5 * auto_sigma(C))
    assert choose_sigma(C, 3.0, sigma_scale=2.0) == 6.0


def test_knn_neighbors_complete_graph_when_k_covers_everyone():
    C, _ = planted_pair_costs(N=6)
    assert knn_neighbors(C, 0) is None and knn_neighbors(C, 5) is None and knn_neighbors(C, 9) is None
    np.testing.assert_array_equal(knn_neighbors(C, 2), nearest_shapes(C, 2))


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("knn", [0, 5])
def test_every_solver_recovers_planted_offsets(solver, knn):
    C, offsets = planted_pair_costs()
    out = solve_labels(C, solver, auto_sigma(C), seed=0, knn=knn)
    assert out["labels"].dtype == np.int64
    assert agreement_up_to_offset(out["labels"], offsets, C.shape[2])[0] == 1.0
    op = CirculantPairwise(C, auto_sigma(C), knn_neighbors(C, knn))
    U = uniform_unary(len(C), C.shape[2], seed=0)
    assert out["energy"] == pytest.approx(mrf.energy(op, U, out["labels"]))
    assert ("converged" in out) == (solver == "lh")


def test_solve_labels_reuses_a_given_operator_and_rejects_unknown_solvers():
    C, _ = planted_pair_costs()
    op = CirculantPairwise(C, auto_sigma(C))
    np.testing.assert_array_equal(solve_labels(C, "lh", auto_sigma(C), 1, op=op)["labels"],
                                  solve_labels(C, "lh", auto_sigma(C), 1)["labels"])
    with pytest.raises(ValueError, match="unknown solver 'icm'"):
        solve_labels(C, "icm", 1.0, 0)


def test_solve_alignment_reports_its_parameters_and_refuses_nan():
    C, offsets = planted_pair_costs()
    out = solve_alignment(C, solver="spectral", sigma_scale=2.0, seed=4, knn=3)
    assert out["sigma"] == pytest.approx(2 * auto_sigma(C))
    assert (out["solver"], out["seed"], out["knn"], out["n_views"]) == ("spectral", 4, 3, C.shape[2])
    bad = C.copy()
    bad[1, 2, 3] = np.nan
    with pytest.raises(ValueError, match="contain NaN"):
        solve_alignment(bad)
