"""Tests for corr_core.alignment.sync (and end-to-end alignment): synthetic collections with planted rotations, noise and
outlier pairs; a course-data equivariance check on 30 chairs."""

import numpy as np
import pytest

from corr_core.alignment.azimuth import agreement_up_to_offset
from corr_core.alignment.circulant import CirculantPairwise
from corr_core.alignment.pair_costs import auto_sigma, mirror_pair_costs, pair_costs
from corr_core.alignment.solvers import uniform_unary
from corr_core.mrf import solve_lh
from corr_core.alignment.sync import projected_power, round_phases, spectral_sync, sync_matrix

from tests.helpers import COURSE_DATA



def synthetic_costs(N=40, V=16, D=50, noise=0.3, outlier_frac=0.0, seed=0):
    """C (N,N,V) of noisy rotated copies of one random shape (offsets planted), with a fraction of pairs made
    outliers by cyclically shifting their cost curve by a random nonzero amount (mirror kept consistent)."""
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(V, D))
    offsets = rng.integers(0, V, size=N)
    F = np.stack([np.roll(base + noise * rng.normal(size=(V, D)), o, axis=0) for o in offsets])
    C = pair_costs(F).astype(np.float64)
    iu, ju = np.triu_indices(N, 1)
    bad = rng.uniform(size=iu.size) < outlier_frac
    shifts = rng.integers(1, V, size=iu.size)
    theta = np.arange(V)
    C[iu[bad], ju[bad]] = C[iu[bad], ju[bad]][np.arange(bad.sum())[:, None], (theta[None] - shifts[bad, None]) % V]
    C[ju, iu] = mirror_pair_costs(C)[ju, iu]
    return C, offsets


def test_synthetic_costs_are_mirror_consistent():
    C, _ = synthetic_costs(N=10, outlier_frac=0.3)
    np.testing.assert_allclose(C, mirror_pair_costs(C))


def test_sync_matrix_is_hermitian_and_rank_one_for_exact_data():
    C, offsets = synthetic_costs(N=10, noise=0.0)
    H = sync_matrix(C)
    np.testing.assert_allclose(H, H.conj().T, atol=1e-12)
    z = np.exp(-2j * np.pi * offsets / 16)
    expected_phase = z[:, None] * z.conj()[None, :]
    off = ~np.eye(10, dtype=bool)
    np.testing.assert_allclose(H[off] / np.abs(H[off]), expected_phase[off], atol=1e-6)


def test_round_phases_recovers_labels_with_arbitrary_global_phase():
    rng = np.random.default_rng(1)
    x = rng.integers(0, 16, size=50)
    z = np.exp(-2j * np.pi * (x + 0.5 + 0.1 * rng.uniform(-1, 1, size=50)) / 16) * np.exp(1j * 0.7)
    assert agreement_up_to_offset(round_phases(z, 16), x, 16)[0] == 1.0


@pytest.mark.parametrize("seed", range(3))
def test_spectral_sync_exact_without_outliers(seed):
    C, offsets = synthetic_costs(seed=seed)
    assert agreement_up_to_offset(spectral_sync(C), offsets, 16)[0] == 1.0


@pytest.mark.parametrize("seed", range(3))
def test_spectral_sync_within_one_step_with_outliers(seed):
    C, offsets = synthetic_costs(seed=seed, outlier_frac=0.3)
    assert agreement_up_to_offset(spectral_sync(C), offsets, 16, tolerance=1)[0] >= 0.95


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("outlier_frac", [0.3, 0.5])
def test_projected_power_and_lh_exact_with_outliers(seed, outlier_frac):
    C, offsets = synthetic_costs(seed=seed, outlier_frac=outlier_frac)
    labels, _ = projected_power(C)
    assert agreement_up_to_offset(labels, offsets, 16)[0] == 1.0
    res = solve_lh(CirculantPairwise(C, auto_sigma(C)), uniform_unary(len(offsets), 16, seed=seed), compute_bound=False)
    assert agreement_up_to_offset(res.labels, offsets, 16)[0] == 1.0


def test_projected_power_log_score():
    C, offsets = synthetic_costs(seed=4, outlier_frac=0.1)
    labels, _ = projected_power(C, score="log")
    assert agreement_up_to_offset(labels, offsets, 16)[0] == 1.0


def _shift_views(F, offsets):
    """F'_i[(v + o_i) % V] = F_i[v]: chair i rotated by o_i steps."""
    return np.stack([np.roll(F[i], o, axis=0) for i, o in enumerate(offsets)])


def _check_equivariance(F, offsets, V):
    """Spectral sync and PPM must move by exactly the planted offsets (up to one global offset); LH too when its
    unary terms are moved with the labels (U'_i = roll(U_i, o_i))."""
    C0, C1 = pair_costs(F), pair_costs(_shift_views(F, offsets))
    sigma = auto_sigma(C0)
    assert auto_sigma(C1) == pytest.approx(sigma, rel=1e-4)
    for solve in (lambda C: spectral_sync(C, sigma), lambda C: projected_power(C, sigma)[0]):
        a, b = solve(C0), solve(C1)
        assert agreement_up_to_offset(b, (a + offsets) % V, V)[0] == 1.0
    U0 = uniform_unary(len(offsets), V, seed=0)
    U1 = np.stack([np.roll(U0[i], o) for i, o in enumerate(offsets)])
    a = solve_lh(CirculantPairwise(C0, sigma), U0, compute_bound=False).labels
    b = solve_lh(CirculantPairwise(C1, sigma), U1, compute_bound=False).labels
    np.testing.assert_array_equal(b, (a + offsets) % V)


def test_equivariance_synthetic():
    rng = np.random.default_rng(11)
    V = 16
    F = rng.normal(size=(20, V, 40)).astype(np.float32)  # unrelated shapes: many near-ties, a hard case
    _check_equivariance(F, rng.integers(0, V, size=20), V)


def _load_chair_features(ids, V=16):
    """skimage-default HoG of each view: blue background -> white, pad to square, gray, 120x120: (n, V, 13689)."""
    import skimage.color
    import skimage.io
    import skimage.transform
    from skimage.feature import hog

    def view(path):
        im = skimage.io.imread(path)[..., :3].copy()
        im[(im[..., 0] == 0) & (im[..., 1] == 0) & (im[..., 2] == 255)] = 255
        h, w = im.shape[:2]
        s = max(h, w)
        sq = np.full((s, s, 3), 255, np.uint8)
        sq[(s - h) // 2:(s - h) // 2 + h, (s - w) // 2:(s - w) // 2 + w] = im
        return skimage.transform.resize(skimage.color.rgb2gray(sq), (120, 120))

    root = COURSE_DATA / "chairs_rendering"
    return np.stack([[hog(view(root / f"{c:03d}_{v}.png")) for v in range(V)] for c in ids]).astype(np.float32)


@pytest.mark.course
@pytest.mark.skipif(not (COURSE_DATA / "chairs_rendering").is_dir(), reason=f"course data not found at {COURSE_DATA}")
def test_course_chairs_equivariance():
    V = 16
    F = _load_chair_features(range(1, 31), V)
    offsets = np.random.default_rng(2024).integers(0, V, size=len(F))
    _check_equivariance(F, offsets, V)


# --- kNN graph and large-N paths ------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", range(2))
def test_spectral_ppm_and_lh_exact_on_knn_graph(seed):
    """Noisy planted rotations, no outliers: all three solvers exact on an 8-nearest graph (60 shapes)."""
    from corr_core.alignment.pair_costs import nearest_shapes
    C, offsets = synthetic_costs(N=60, seed=seed)
    sigma = auto_sigma(C)
    nb = nearest_shapes(C, 8)
    assert agreement_up_to_offset(spectral_sync(C, sigma, nb), offsets, 16)[0] == 1.0
    assert agreement_up_to_offset(projected_power(C, sigma, neighbors=nb)[0], offsets, 16)[0] == 1.0
    op = CirculantPairwise(C, sigma, nb)
    assert op.sparse
    res = solve_lh(op, uniform_unary(60, 16, seed=seed), compute_bound=False)
    assert agreement_up_to_offset(res.labels, offsets, 16)[0] == 1.0


def test_projected_power_on_knn_graph_survives_outlier_pairs():
    """With 20% outlier pairs a sparse graph has fewer votes per shape (spectral sync then drops to ~0.85 here,
    see docs/scale.md); the debiased projected power method still recovers every offset."""
    from corr_core.alignment.pair_costs import nearest_shapes
    C, offsets = synthetic_costs(N=60, seed=0, outlier_frac=0.2)
    sigma = auto_sigma(C)
    labels, _ = projected_power(C, sigma, neighbors=nearest_shapes(C, 8))
    assert agreement_up_to_offset(labels, offsets, 16)[0] == 1.0


def test_sync_matrix_on_knn_graph_is_the_complete_one_restricted():
    from corr_core.alignment.pair_costs import nearest_shapes
    C, _ = synthetic_costs(N=15, seed=3, outlier_frac=0.3)
    nb = nearest_shapes(C, 2)
    mask = np.zeros((15, 15), dtype=bool)
    mask[np.repeat(np.arange(15), 2), nb.ravel()] = True
    mask |= mask.T
    np.testing.assert_allclose(sync_matrix(C, 2.0, nb), sync_matrix(C, 2.0) * mask, atol=1e-13)


@pytest.mark.parametrize("use_knn", [False, True])
def test_lanczos_path_gives_the_dense_eigensolve_labels(monkeypatch, use_knn):
    """Above DENSE_EIGH_MAX shapes spectral sync uses eigsh for the top eigenvector: same labels as eigh."""
    import corr_core.alignment.sync as sync
    from corr_core.alignment.pair_costs import nearest_shapes
    C, offsets = synthetic_costs(N=50, seed=5, outlier_frac=0.3)
    nb = nearest_shapes(C, 6) if use_knn else None
    dense_labels = spectral_sync(C, None, nb)
    monkeypatch.setattr(sync, "DENSE_EIGH_MAX", 10)
    lanczos_labels = spectral_sync(C, None, nb)
    assert agreement_up_to_offset(lanczos_labels, dense_labels, 16)[0] == 1.0
    if not use_knn:
        assert agreement_up_to_offset(lanczos_labels, offsets, 16, tolerance=1)[0] >= 0.95
