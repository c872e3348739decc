"""Tests for corr_core.alignment.continuous: band-limited interpolation of C_ij(theta), continuous argmin, the
least-squares refinement of the labels, and the continuous error on generated chairs at random azimuths."""

import warnings

import numpy as np
import pytest

from corr_core.alignment.continuous import continuous_argmin, interpolate_costs, refine_labels, steps_to_degrees
from corr_core.alignment.measures import continuous_error
from corr_core.alignment.solvers import solve_alignment


def cosine_costs(t: np.ndarray, V: int) -> np.ndarray:
    """C (N, N, V) of a band-limited cost 1 - cos(2 pi (theta - (t_j - t_i)) / V), minimum at t_j - t_i."""
    theta = np.arange(V)
    d = t[None, :] - t[:, None]
    return 1.0 - np.cos(2 * np.pi * (theta[None, None, :] - d[:, :, None]) / V)


@pytest.mark.parametrize("V", [15, 16])
def test_interpolation_passes_through_the_samples_and_finds_a_fractional_minimum(V):
    rng = np.random.default_rng(0)
    C = rng.uniform(size=(3, V))
    np.testing.assert_allclose(interpolate_costs(C, np.tile(np.arange(V, dtype=float), (3, 1))), C, atol=1e-12)
    theta = np.arange(V)
    shifted = 2.0 - np.cos(2 * np.pi * (theta - 3.3) / V) - 0.3 * np.cos(4 * np.pi * (theta - 3.3) / V)
    assert continuous_argmin(shifted) == pytest.approx(3.3, abs=1e-6)


def test_refine_labels_recovers_planted_fractional_offsets_and_ignores_outlier_pairs():
    V, N = 16, 12
    t = np.random.default_rng(1).uniform(0, V, N)
    C = cosine_costs(t, V)
    C[0, 5] = np.roll(C[0, 5], 6)  # one pair claims a rotation 6 steps off: not within one view of the labels
    C[5, 0] = C[0, 5][(-np.arange(V)) % V]
    labels = np.rint(t).astype(int) % V
    refined = refine_labels(C, labels, sigma=1.0)
    err = continuous_error(steps_to_degrees(refined, V), steps_to_degrees(t, V), resolution_deg=0.001)
    assert err["max_error_deg"] < 0.01
    assert np.all(np.abs(refined - labels) <= 0.5 + 1e-6)  # the gauge keeps round(t) at the labels
    assert continuous_error(labels * 360.0 / V, steps_to_degrees(t, V))["mean_error_deg"] > 1.0


def test_continuous_error_is_up_to_one_offset_and_modulo_symmetry():
    truth = np.array([10.0, 100.0, 200.0, 300.0])
    est = truth + 40.0 + np.array([1.0, -1.0, 0.0, 0.0])
    e = continuous_error(est, truth, resolution_deg=0.5)
    assert e["mean_error_deg"] == pytest.approx(0.5) and e["offset_deg"] == pytest.approx(40.0)
    orders = np.array([1, 1, 4, 0])
    est[2] += 90.0       # a square shape one quarter turn away is right
    est[3] = 0.0         # a round shape may take any angle
    e = continuous_error(est, truth, orders, resolution_deg=0.5)
    assert e["mean_error_deg"] == pytest.approx(2.0 / 3.0) and e["n"] == 3


@pytest.mark.parametrize("n", [3, 100])   # 100 shapes: the 36,000 offsets span 55 of the function's blocks
def test_continuous_error_finds_the_offset_of_least_mean_error_over_the_whole_grid(n):
    rng = np.random.default_rng(n)
    truth = rng.uniform(0, 360, n)
    est = truth + 301.37 + rng.normal(0, 2.0, n)       # best offset far into the grid, past the first blocks
    orders = rng.integers(0, 4, n)
    e = continuous_error(est, truth, orders)
    keep = orders != 0
    period = 360.0 / orders[keep]
    offsets = np.arange(0.0, 360.0, 0.01)
    d = (est - truth)[keep][None, :] - offsets[:, None]
    means = np.abs(np.mod(d + period / 2, period) - period / 2).mean(axis=1)     # every offset, written apart
    best = int(np.argmin(means))
    assert e["offset_deg"] == pytest.approx(offsets[best], abs=1e-9)
    assert e["mean_error_deg"] == pytest.approx(means[best], rel=1e-12)


@pytest.fixture(scope="module")
def continuous_chairs(tmp_path_factory):
    """Pair costs (N, N, 16) and true degrees (N,) of 12 generated chairs at random continuous azimuths."""
    from corr_core.generate.chairs import write_chair_collection
    from shapecorr.alignment import hog, views

    out = write_chair_collection(tmp_path_factory.mktemp("cont") / "chairs", n=12, seed=0, continuous=True)
    from corr_core.alignment.pair_costs import pair_costs
    with warnings.catch_warnings():  # mesh repairs of the generated boxes may be reported
        warnings.simplefilter("ignore", UserWarning)
        F = np.stack([hog(views([f], image_size=96)) for f in out["files"]])
    return pair_costs(F), np.array(out["azimuth_deg"])


def test_generated_chairs_at_continuous_azimuths_within_two_degrees(continuous_chairs):
    C, truth = continuous_chairs
    sol = solve_alignment(C, solver="spectral")
    err = continuous_error(sol["angles_deg"], truth)
    labels_err = continuous_error(sol["labels"] * 22.5, truth)
    assert err["mean_error_deg"] <= 2.0, err
    assert err["mean_error_deg"] < labels_err["mean_error_deg"] / 3  # much better than the nearest view
    steps = np.rint(sol["angles_deg"] / 22.5).astype(int) % 16
    assert np.mean(steps == sol["labels"]) >= 0.9  # the nearest view of the angle is (almost always) the label
