"""Correspondence measures: matrices, accuracy, per-method reports, geodesic error curves, dense-map summaries."""
import numpy as np
import pytest

from corr_core.correspondence.measures import (accuracy, correspondence_matrix, dense_map_summary, frequency_matrix,
                                               geodesic_error_curve, geodesic_errors, method_report, top_confusions)
from corr_core.geometry.primitives import surface_area
from tests.helpers import sphere


def test_correspondence_and_frequency_matrices():
    C = correspondence_matrix(np.array([2, 0, 1]), 4)
    assert C.dtype == np.uint8
    np.testing.assert_array_equal(C, [[0, 0, 1, 0], [1, 0, 0, 0], [0, 1, 0, 0]])
    F = frequency_matrix([C, correspondence_matrix(np.array([2, 1, 0]), 4)])
    np.testing.assert_allclose(F, [[0, 0, 1, 0], [0.5, 0.5, 0, 0], [0.5, 0.5, 0, 0]])
    np.testing.assert_allclose(F.sum(1), 1)
    with pytest.raises(ValueError):
        correspondence_matrix(np.array([4]), 4)


def test_accuracy():
    assert accuracy(np.array([0, 1, 2, 3]), np.array([0, 1, 3, 2])) == 0.5
    with pytest.raises(ValueError):
        accuracy(np.array([0, 1]), np.array([0, 1, 2]))


def test_error_curve_matches_brute_force():
    rng = np.random.default_rng(0)
    err = rng.uniform(0, 0.3, 200)
    thr = np.linspace(0, 0.25, 51)
    curve = geodesic_error_curve(err, thr)
    np.testing.assert_allclose(curve, [(err <= t).mean() for t in thr])
    assert geodesic_error_curve(np.zeros(3))[0] == 1.0  # zero error counts at threshold 0


def test_geodesic_errors_on_unit_sphere():
    V, F = sphere(2000)
    true = np.array([0, 10, 500, 1500])
    pred = np.array([0, 1999, 900, 1500])
    err = geodesic_errors(V, F, pred, true)
    exact = np.arccos(np.clip(np.sum(V[pred] * V[true], axis=1), -1, 1)) / np.sqrt(surface_area(V, F))
    assert err[0] == 0 and err[3] == 0
    np.testing.assert_allclose(err, exact, atol=0.01)
    assert surface_area(V, F) == pytest.approx(4 * np.pi, rel=0.01)


def test_top_confusions_counts_wrong_pairs_most_frequent_first():
    rows = ["A", "B", "C"]
    mats = [correspondence_matrix(np.array(p), 3) for p in ([1, 0, 2], [1, 0, 2], [0, 2, 1])]
    assert top_confusions(mats, rows) == {"A -> B": 2, "B -> A": 2, "B -> C": 1, "C -> B": 1}
    assert list(top_confusions(mats, rows, k=1)) == ["A -> B"]


def test_method_report_accuracy_matrices_and_frequency():
    rows = ["A", "B", "C"]
    preds = {"m1": np.array([0, 1, 2]), "m2": np.array([1, 0, 2])}
    r = method_report(preds, rows)
    assert r["accuracy"] == pytest.approx(2 / 3) and r["per_mesh"] == {"m1": 1.0, "m2": pytest.approx(1 / 3)}
    assert r["matrices"]["m2"] == [[0, 1, 0], [1, 0, 0], [0, 0, 1]]
    np.testing.assert_allclose(r["frequency"], [[0.5, 0.5, 0], [0.5, 0.5, 0], [0, 0, 1]])
    assert r["confusions"] == {"A -> B": 1, "B -> A": 1}


def test_dense_map_summary_fractions():
    s = dense_map_summary(np.array([0.0, 0.04, 0.08, 0.2, 0.3]))
    assert s == {"within_0.05": 0.4, "within_0.10": 0.6, "within_0.25": 0.8, "mean_error": pytest.approx(0.124),
                 "n_points": 5}
