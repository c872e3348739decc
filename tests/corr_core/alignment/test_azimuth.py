"""Tests for corr_core.alignment.azimuth."""
import numpy as np
import pytest

from corr_core.alignment.azimuth import (agreement_up_to_offset, circular_distance, labels_to_angles,
                               relabel_by_offset)


def test_labels_to_angles():
    np.testing.assert_allclose(labels_to_angles(np.array([0, 4, 8, 15, 16]), 16),
                               [0, np.pi / 2, np.pi, 2 * np.pi * 15 / 16, 0])


def test_circular_distance():
    np.testing.assert_array_equal(circular_distance(np.array([0, 0, 15, 3]), np.array([1, 15, 0, 11]), 16),
                                  [1, 1, 1, 8])


def test_agreement_exact_with_global_offset():
    rng = np.random.default_rng(0)
    b = rng.integers(0, 16, size=50)
    a = relabel_by_offset(b, 5, 16)
    assert agreement_up_to_offset(a, b, 16) == (1.0, 5)
    frac, off = agreement_up_to_offset(b, a, 16)
    assert frac == 1.0 and off == 11


def test_agreement_counts_only_items_within_tolerance():
    b = np.zeros(10, dtype=int)
    a = np.array([3, 3, 3, 3, 3, 3, 4, 2, 9, 11])  # offset 3: six exact, two one step off, two far
    assert agreement_up_to_offset(a, b, 16, tolerance=0) == (pytest.approx(0.6), 3)
    frac, off = agreement_up_to_offset(a, b, 16, tolerance=1)
    assert frac == pytest.approx(0.8) and off == 3


def test_agreement_wraps_around():
    a = np.array([15, 0, 1])
    b = np.array([0, 1, 2])
    assert agreement_up_to_offset(a, b, 16) == (1.0, 15)


def test_shape_mismatch_raises():
    with pytest.raises(ValueError):
        agreement_up_to_offset(np.zeros(3, int), np.zeros(4, int), 16)
