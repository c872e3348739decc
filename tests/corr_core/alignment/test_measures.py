"""Measures of an alignment solution: agreement, seed stability, equivariance, solver quality, ground truth."""
import numpy as np
import pytest

from corr_core.alignment.measures import (agreement, equivariance, evaluate_alignment, ground_truth_agreement,
                                          mode_agreement, seed_stability, solver_quality)
from corr_core.alignment.solvers import solve_alignment
from tests.helpers import planted_pair_costs


@pytest.fixture(scope="module")
def planted():
    C, offsets = planted_pair_costs(N=10, V=8)
    names = [f"{i:03d}" for i in range(len(C))]
    return C, offsets, {"names": names, **solve_alignment(C, solver="lh")}


def test_agreement_is_up_to_one_offset_with_a_one_view_tolerance():
    a = np.array([0, 1, 2, 3])
    assert agreement(a, (a + 5) % 8, 8) == {"exact": 1.0, "within_one_view": 1.0, "n": 4}
    off_by_one = np.array([0, 1, 2, 4])
    assert agreement(a, off_by_one, 8) == {"exact": 0.75, "within_one_view": 1.0, "n": 4}


def test_seed_stability_and_equivariance_are_perfect_on_clean_data(planted):
    C, _, sol = planted
    assert seed_stability(C, sol, [0, 1, 2]) == {"min": 1.0, "mean": 1.0, "n_seeds": 3}
    assert seed_stability(C, sol, [sol["seed"]]) == {"min": 1.0, "mean": 1.0, "n_seeds": 1}
    assert equivariance(C, sol, shift_seed=7) == 1.0


def test_equivariance_detects_a_solver_that_ignores_the_data(planted):
    C, _, sol = planted
    constant = {**sol, "labels": np.zeros(len(C), dtype=np.int64)}  # claims every shape has label 0
    assert equivariance(C, constant, shift_seed=7) < 0.5


def test_solver_quality_orders_the_energies(planted):
    C, _, sol = planted
    q = solver_quality(C, sol, {"other": (np.asarray(sol["labels"]) + 1) % 8}, restarts=3, seed=0)
    assert q["upper_bound"] >= q["energy"] >= q["best_of_random_restarts"] - 1e-9
    assert q["energy"] > q["random_labeling"]
    assert q["energy_other"] == pytest.approx(q["energy"], rel=0.2)  # a global shift changes only the unary terms


def test_ground_truth_and_mode_agreement_on_common_shapes(planted):
    C, offsets, sol = planted
    names, labels = sol["names"], np.asarray(sol["labels"])
    truth = {n: int(o) for n, o in zip(names, offsets)}
    truth.pop(names[0])
    gt = ground_truth_agreement(names, labels, truth, 8, {"lh": labels, "bad": (labels + np.arange(10)) % 8})
    assert gt["exact"] == 1.0 and gt["n"] == 9 and gt["exact_lh"] == 1.0 and gt["exact_bad"] < 0.5
    other = {"names": names[:4] + ["zzz"], "labels": list((labels[:4] + 3) % 8) + [0]}
    assert mode_agreement(names, labels, other, 8) == {"exact": 1.0, "within_one_view": 1.0, "n": 4}
    assert mode_agreement(names, labels, {"names": ["zzz"], "labels": [0]}, 8) is None


def test_evaluate_alignment_collects_every_measure(planted):
    C, offsets, sol = planted
    truth = {n: int(o) for n, o in zip(sol["names"], offsets)}
    m = evaluate_alignment(C, sol, truth, other=sol, seeds=[0, 1], restarts=2)
    assert list(m) == ["n_shapes", "n_views", "solver", "sigma", "labels", "angle_deg", "angles_deg",
                       "symmetry_order", "seed_stability", "equivariance", "agreement_with", "solver_quality", "ground_truth", "mode_agreement"]
    assert m["ground_truth"]["exact"] == 1.0 and m["mode_agreement"]["exact"] == 1.0
    assert set(m["agreement_with"]) == {"spectral", "ppm"}
    assert m["angle_deg"]["001"] == m["labels"]["001"] * 45.0
    lean = evaluate_alignment(C, sol, compare_solvers=False, seeds=[0], restarts=2)
    assert "agreement_with" not in lean and "ground_truth" not in lean and "mode_agreement" not in lean
