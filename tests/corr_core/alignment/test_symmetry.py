"""Tests for corr_core.alignment.symmetry: orders read off C_ii, and symmetric shapes placed without steering
the asymmetric ones (synthetic features and generated tables)."""

import warnings

import numpy as np
import pytest

from corr_core.alignment.azimuth import agreement_up_to_offset
from corr_core.alignment.measures import agreement_modulo, ground_truth_agreement
from corr_core.alignment.pair_costs import pair_costs
from corr_core.alignment.solvers import solve_alignment
from corr_core.alignment.symmetry import symmetry_orders, symmetry_periods


def symmetrized(base, order):
    """(V, D) features of the ``order``-fold symmetric version of a shape with features base (V, D): the mean of
    its turns by multiples of V/order (order 0: of every turn), so it matches ``base`` best at turn 0."""
    V = len(base)
    turns = range(V) if order == 0 else range(0, V, V // order)
    return np.mean([np.roll(base, t, axis=0) for t in turns], axis=0)


def collection(orders, V=16, D=30, noise=0.05, seed=0):
    """Features (N, V, D) of noisy symmetrized copies (``symmetrized``) of one random shape, shape i rolled by a
    random planted offset; the noise has each shape's symmetry too. Returns (features, offsets)."""
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(V, D))
    offsets = rng.integers(0, V, len(orders))
    F = np.stack([np.roll(symmetrized(base + noise * rng.normal(size=(V, D)), k), o, axis=0)
                  for k, o in zip(orders, offsets)])
    return F, offsets


def test_orders_are_read_off_the_self_costs():
    orders = [1, 1, 2, 4, 0, 8, 1]
    F, _ = collection(orders)
    assert symmetry_orders(pair_costs(F)).tolist() == orders


@pytest.mark.parametrize("solver", ["spectral", "ppm", "lh"])
def test_symmetric_shapes_are_placed_modulo_their_symmetry(solver):
    orders = np.array([1] * 10 + [2] * 6 + [4] * 6 + [0] * 4)
    F, offsets = collection(list(orders), noise=0.5, seed=2)
    C = pair_costs(F)
    sol = solve_alignment(C, solver=solver)
    assert sol["symmetry_order"].tolist() == orders.tolist()
    assert agreement_modulo(sol["labels"], offsets, 16, symmetry_periods(orders, 16)) == 1.0


def test_a_collection_without_asymmetric_shapes_is_synchronized_on_the_harmonic():
    orders = np.array([2] * 6 + [4] * 6 + [0] * 3)
    F, offsets = collection(list(orders), noise=0.5, seed=3)
    sol = solve_alignment(pair_costs(F), solver="spectral")
    assert agreement_modulo(sol["labels"], offsets, 16, symmetry_periods(orders, 16)) == 1.0


def test_without_symmetry_handling_spectral_sync_loses_the_symmetric_shapes():
    """The first harmonic of a k-fold periodic kernel vanishes: the symmetric shapes' phases are noise."""
    orders = np.array([1] * 10 + [2] * 6 + [4] * 6)
    F, offsets = collection(list(orders), noise=0.5, seed=2)
    periods = symmetry_periods(orders, 16)
    plain = solve_alignment(pair_costs(F), solver="spectral", symmetric=False)
    handled = solve_alignment(pair_costs(F), solver="spectral")
    assert agreement_modulo(plain["labels"], offsets, 16, periods) < 0.8
    assert agreement_up_to_offset(handled["labels"][:10], plain["labels"][:10], 16)[0] == 1.0  # chairs kept


def test_ground_truth_is_counted_modulo_symmetry():
    names = ["a", "b", "c", "d"]
    truth = {"a": 0, "b": 3, "c": 5, "d": 7}
    labels = np.array([1, 4, 10, 2])        # c is a quarter turn (4 steps) + 1 away, d is round
    plain = ground_truth_agreement(names, labels, truth, 16)
    sym = ground_truth_agreement(names, labels, truth, 16, orders=np.array([1, 1, 4, 0]))
    assert plain["exact"] == 0.5 and sym["exact"] == 1.0 and sym["modulo_symmetry"]


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    """Pair costs and ground truth of 6 generated tables (2 of each kind) and 4 chairs."""
    from corr_core.generate.tables import write_table_collection
    from shapecorr.alignment import hog, views

    out = write_table_collection(tmp_path_factory.mktemp("tables") / "t", n=6, n_chairs=4, seed=1)
    files = [f"{out['out_dir']}/{n}.obj" for n in out["names"]]
    with warnings.catch_warnings():  # mesh repairs of the generated boxes may be reported
        warnings.simplefilter("ignore", UserWarning)
        F = np.stack([hog(views([f], image_size=96)) for f in files])
    return pair_costs(F), out


def test_generated_tables_symmetry_is_detected_and_used(tables):
    from corr_core.alignment.measures import continuous_error

    C, out = tables
    sol = solve_alignment(C, solver="spectral")
    assert sol["symmetry_order"].tolist() == out["symmetry_order"]
    err = continuous_error(sol["angles_deg"], np.array(out["azimuth_deg"]), np.array(out["symmetry_order"]))
    assert err["mean_error_deg"] <= 2.0 and err["n"] == 8


def test_equivariance_and_seed_stability_use_the_symmetry_handling():
    from corr_core.alignment.measures import equivariance, seed_stability

    orders = np.array([1] * 10 + [2] * 6 + [4] * 6)
    F, _ = collection(list(orders), noise=0.5, seed=2)
    C = pair_costs(F)
    sol = solve_alignment(C, solver="spectral")
    assert equivariance(C, sol, shift_seed=4) == 1.0
    assert seed_stability(C, sol, [0, 1, 2])["min"] == 1.0
