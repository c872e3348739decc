"""Evaluation measures, plots, and landmark-file reading."""
import warnings

import numpy as np
import pytest

from corr_core.correspondence.measures import (accuracy, correspondence_matrix, frequency_matrix, geodesic_error_curve,
                                  geodesic_errors, plot_error_curves, plot_frequency_matrix, surface_area)
from corr_core.correspondence.landmarks import read_landmarks
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


def test_plots_are_written(tmp_path):
    F = frequency_matrix([correspondence_matrix(np.array([0, 2, 1]), 3), correspondence_matrix(np.arange(3), 3)])
    names = ["Left Toe", "Right Toe", "Vertex"]
    plot_frequency_matrix(F, names, names, "test", tmp_path / "f.png")
    thr = np.linspace(0, 0.25, 51)
    plot_error_curves({"a": (thr, np.linspace(0, 1, 51)), "b": (thr, np.linspace(0.5, 1, 51))}, tmp_path / "c.png")
    assert (tmp_path / "f.png").stat().st_size > 1000 and (tmp_path / "c.png").stat().st_size > 1000


def test_read_landmarks_named_and_bare(tmp_path):
    p = tmp_path / "lm.txt"
    p.write_text("361,Left Toe\n368,Right Toe\n12464,Vertex")  # no trailing newline
    ids, names = read_landmarks(p, 12498)
    np.testing.assert_array_equal(ids, [361, 368, 12464])
    assert names == ["Left Toe", "Right Toe", "Vertex"]
    q = tmp_path / "bare.txt"
    q.write_text("5\n0\n9\n")
    ids, names = read_landmarks(q, 10)
    np.testing.assert_array_equal(ids, [5, 0, 9])
    assert names == ["5", "0", "9"]


def test_read_landmarks_detects_one_based(tmp_path):
    p = tmp_path / "one_based.txt"
    p.write_text("10\n3\n1\n")
    with pytest.warns(UserWarning, match="1-based"):
        ids, _ = read_landmarks(p, 10)
    np.testing.assert_array_equal(ids, [9, 2, 0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ids, _ = read_landmarks(p)  # no vertex count: ids taken as they are
    np.testing.assert_array_equal(ids, [10, 3, 1])


def test_read_landmarks_errors_name_file_and_line(tmp_path):
    p = tmp_path / "bad.txt"
    p.write_text("1,A\n0,B\n12,C\n")
    with pytest.raises(ValueError, match=r"bad.txt:3: vertex id 12 is out of range"):
        read_landmarks(p, 10)
    q = tmp_path / "mixed.txt"
    q.write_text("0\n10\n")
    with pytest.raises(ValueError, match=r"mixed.txt:2"):
        read_landmarks(q, 10)
    r = tmp_path / "junk.txt"
    r.write_text("3\nhello\n")
    with pytest.raises(ValueError, match=r"junk.txt:2"):
        read_landmarks(r)
