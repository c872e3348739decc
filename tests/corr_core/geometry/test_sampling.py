"""Tests for corr_core.geometry.sampling."""
import numpy as np
import pytest

from corr_core.geometry.sampling import farthest_point_samples


def brute_force_fps(P, k, start, dist):
    chosen = [start]
    while len(chosen) < k:
        best, best_d = None, -1.0
        for i in range(len(P)):
            if i in chosen:
                continue
            d = min(dist(P[i], P[j]) for j in chosen)
            if d > best_d:
                best, best_d = i, d
        chosen.append(best)
    return chosen


def test_points_on_a_line():
    P = np.c_[np.arange(11.0), np.zeros(11), np.zeros(11)]
    assert farthest_point_samples(P, 3, start=0).tolist() == [0, 10, 5]
    assert farthest_point_samples(P, 2, start=4).tolist() == [4, 10]


def test_matches_brute_force_euclidean():
    rng = np.random.default_rng(3)
    P = rng.normal(size=(60, 3))
    got = farthest_point_samples(P, 12, start=7)
    ref = brute_force_fps(P, 12, 7, lambda a, b: np.linalg.norm(a - b))
    assert got.tolist() == ref
    assert len(set(got.tolist())) == 12
    np.testing.assert_array_equal(got, farthest_point_samples(P, 12, start=7))   # deterministic


def test_distance_callback_replaces_euclidean():
    """Points on a circle with arc-length (geodesic) distances: FPS spreads them by arc length."""
    rng = np.random.default_rng(5)
    t = np.sort(rng.uniform(0, 2 * np.pi, 80))
    P = np.c_[np.cos(t), np.sin(t), np.zeros_like(t)]

    def arc(i):
        d = np.abs(t - t[i])
        return np.minimum(d, 2 * np.pi - d)

    got = farthest_point_samples(P, 6, start=0, distances=arc)
    ref = brute_force_fps(np.c_[t], 6, 0, lambda a, b: min(abs(a[0] - b[0]), 2 * np.pi - abs(a[0] - b[0])))
    assert got.tolist() == ref


def test_rejects_bad_arguments():
    P = np.zeros((5, 3))
    with pytest.raises(ValueError):
        farthest_point_samples(P, 6)
    with pytest.raises(ValueError):
        farthest_point_samples(P, 2, start=5)
