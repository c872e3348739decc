"""The faster numerical paths of the dense basis and functional maps give the answers of the plain ones (kept
distance rows, face frames and template point features among them):
basis eigenpairs (mid-band shift with its fallback), farthest-point samples (buffered Euclidean path), float32 nearest rows (brute force and by cells), the normal
equations of fmap_from_p2p, the row-decoupled functional-map fit, ZoomOut's sample-then-vertex schedule, and the
benchmark's CPU-time ratios."""
from __future__ import annotations

import numpy as np
import pytest

from corr_core.correspondence.dense import basis as dense_basis
from corr_core.correspondence.dense import fmaps, mesh_basis, zoomout
from corr_core.geometry.laplacian import eigenpairs, laplacian_and_mass
from corr_core.geometry.primitives import face_areas
from corr_core.geometry.sampling import farthest_point_samples
from tests.helpers import sphere


@pytest.fixture(scope="module")
def ellipsoid():
    V, F = sphere(n=600)
    V = V * np.array([1.0, 0.6, 0.35])
    return V, F


def _same_spectrum(evals, evecs, ref_evals, ref_evecs, M):
    assert np.allclose(evals, ref_evals, rtol=1e-8, atol=1e-10)
    overlap = np.abs(ref_evecs.T @ (M @ evecs))          # (k, k): each vector equal up to sign, or the same
    assert np.allclose(np.linalg.svd(overlap, compute_uv=False), 1.0, atol=1e-6)   # subspace of a near-double one


def test_basis_eigenpairs_equal_the_shared_eigenpairs(ellipsoid):
    V, F = ellipsoid
    L, M = laplacian_and_mass(V, F)
    evals, evecs = dense_basis.basis_eigenpairs(L, M, 20, float(face_areas(V, F).sum()))
    _same_spectrum(evals, evecs, *eigenpairs(V, F, k=20), M)
    assert np.allclose(evecs.T @ (M @ evecs), np.eye(20), atol=1e-8)


def test_basis_eigenpairs_fall_back_when_the_weyl_shift_misses_the_bottom(ellipsoid):
    """An area 50x too small puts the shift far above the 20 smallest eigenvalues: the nearest 20 are mid-band;
    the check must notice it and solve again near 0."""
    V, F = ellipsoid
    L, M = laplacian_and_mass(V, F)
    evals, evecs = dense_basis.basis_eigenpairs(L, M, 20, float(face_areas(V, F).sum()) / 50.0)
    _same_spectrum(evals, evecs, *eigenpairs(V, F, k=20), M)


def test_basis_eigenpairs_are_bit_identical_run_to_run(ellipsoid):
    V, F = ellipsoid
    a = mesh_basis(V, F, k=15, n_samples=50)
    b = mesh_basis(V, F, k=15, n_samples=50)
    assert np.array_equal(a.evecs, b.evecs) and np.array_equal(a.evals, b.evals)


def _plain_farthest_samples(V, k, start):
    """The sampler's greedy rule with numpy's own norm per step (the reference of its buffered fast path)."""
    return farthest_point_samples(V, k, start=start, distances=lambda i: np.linalg.norm(V - V[i], axis=1))


def test_farthest_samples_equal_the_plain_greedy_rule(ellipsoid):
    V, _ = ellipsoid
    V = np.vstack([V, V[:3]])                             # duplicated points: ties and zero distances
    for start in (0, 7):
        assert np.array_equal(farthest_point_samples(V, 200, start=start), _plain_farthest_samples(V, 200, start))
    assert np.array_equal(farthest_point_samples(V, len(V), start=0), _plain_farthest_samples(V, len(V), 0))


def test_nearest_rows_is_the_exact_nearest_neighbour_with_lowest_index_ties():
    rng = np.random.default_rng(3)
    points = rng.normal(size=(700, 40))
    queries = points[rng.integers(0, 700, 300)] + 1e-3 * rng.normal(size=(300, 40))
    d = ((queries[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    assert np.array_equal(fmaps.nearest_rows(queries, points, chunk=64), np.argmin(d, axis=1))
    doubled = np.vstack([points[:5], points[:5]])          # rows 0..4 repeated as 5..9
    assert np.array_equal(fmaps.nearest_rows(points[:5], doubled), np.arange(5))
    with pytest.raises(ValueError, match="nearest_rows"):
        fmaps.nearest_rows(queries, points[:, :3])


def test_nearest_rows_is_exact_where_float32_scores_cannot_tell_the_rows_apart():
    """Far from the origin float32 ``|y|^2 - 2 x.y`` rounds by more than the gaps between the candidates: the
    answer must still be the exact nearest row of the float32 inputs, ties to the lowest row."""
    rng = np.random.default_rng(8)
    points = (100.0 + 0.01 * rng.normal(size=(600, 20))).astype(np.float32)
    points[300:310] = points[200:210]                                   # bit-identical duplicates
    queries = (points[rng.integers(0, 600, 250)] + 0.003 * rng.normal(size=(250, 20))).astype(np.float32)
    queries[:10] = points[300:310]                                      # queries that sit on a duplicate
    exact = ((queries[:, None, :].astype(np.float64) - points[None, :, :].astype(np.float64)) ** 2).sum(axis=2)
    expected = np.argmin(exact, axis=1)
    assert np.array_equal(expected[:10], np.arange(200, 210))
    for chunk in (7, 256):
        assert np.array_equal(fmaps.nearest_rows(queries, points, chunk=chunk), expected)


def test_nearest_rows_scores_many_near_ties_in_bounded_memory():
    """Every row a near tie in float32 (64 queries x 5,000 rows in 100 dimensions, all within rounding): the exact
    second scoring goes through the candidates in slices, not one (320,000 x 100) float64 array (512 MB for the
    two operands)."""
    import tracemalloc

    rng = np.random.default_rng(9)
    points = (100.0 + 0.01 * rng.normal(size=(5000, 100))).astype(np.float32)
    queries = points[:64] + np.float32(0.001)
    tracemalloc.start()
    try:
        found = fmaps.nearest_rows(queries, points)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    exact = ((queries[:, None, :].astype(np.float64) - points[None].astype(np.float64)) ** 2).sum(axis=2)
    assert np.array_equal(found, np.argmin(exact, axis=1))
    assert peak < 100e6, f"{peak / 1e6:.0f} MB"


def _random_cells(n_points: int, n_centres: int, seed: int) -> fmaps.RowCells:
    """A partition with no geometric sense: the pruned search must stay exact, only slower."""
    rng = np.random.default_rng(seed)
    centres = rng.choice(n_points, n_centres, replace=False)
    owner = rng.integers(0, n_centres, n_points)
    owner[centres] = np.arange(n_centres)
    return fmaps.RowCells(centres, owner, rng.permutation(n_centres))


def test_nearest_rows_by_cells_is_the_brute_force_answer(ellipsoid):
    rng = np.random.default_rng(5)
    points = rng.normal(size=(900, 30))
    queries = np.vstack([points[rng.integers(0, 900, 200)] + 1e-3 * rng.normal(size=(200, 30)),
                         points[:50],                                   # distance 0: float32 cancellation
                         rng.normal(size=(100, 30))])
    brute = fmaps.nearest_rows(queries, points)
    for seed in range(3):
        assert np.array_equal(fmaps.nearest_rows(queries, points, cells=_random_cells(900, 40, seed)), brute)
    doubled = np.vstack([points[:5], points[:5]])                        # ties go to the lowest row
    assert np.array_equal(fmaps.nearest_rows(points[:5], doubled, cells=_random_cells(10, 2, 0)), np.arange(5))
    far = 100.0 + 0.01 * points                      # float32 rounding of |x|^2 - 2 x.y as large as the gaps:
    near = far[:300] + 0.003 * rng.normal(size=(300, 30))       # the bounds' slack keeps the brute force's answer
    for seed in range(3):
        assert np.array_equal(fmaps.nearest_rows(near, far, cells=_random_cells(900, 40, seed)),
                              fmaps.nearest_rows(near, far))
    # a mesh's spectral embedding with the basis's own cells, the way ZoomOut searches every vertex
    V, F = ellipsoid
    B = mesh_basis(V, F, k=30, n_samples=200)
    cells = B.vertex_cells(n_centres=60, n_regions=8)
    Q, _ = np.linalg.qr(rng.normal(size=(30, 30)))
    target_rows = B.evecs @ (np.eye(30) + 0.3 * Q).T
    assert np.array_equal(fmaps.nearest_rows(B.evecs[B.samples], target_rows, cells=cells),
                          fmaps.nearest_rows(B.evecs[B.samples], target_rows))
    with pytest.raises(ValueError, match="cells partition"):
        fmaps.nearest_rows(queries, points[:100], cells=_random_cells(900, 40, 0))


@pytest.mark.parametrize("rows", [300, 12])               # well-posed (normal equations) and rank-deficient (SVD)
def test_fmap_from_p2p_is_the_least_squares_solution(rows):
    rng = np.random.default_rng(rows)
    Phi_S = rng.normal(size=(rows, 20))
    Phi_T = rng.normal(size=(400, 25))
    p2p = rng.integers(0, 400, rows)
    expected = np.linalg.lstsq(Phi_S, Phi_T[p2p], rcond=None)[0]
    assert np.allclose(fmaps.fmap_from_p2p(p2p, Phi_S, Phi_T), expected, atol=1e-9)


def test_row_decoupled_fit_equals_the_full_system():
    """Without the orientation term the fit solves one small system per row of C; with a zero orientation
    operator it goes through the full ks * kt system: the same minimizer."""
    rng = np.random.default_rng(5)
    ks, kt, q = 9, 7, 12
    A_S, A_T = rng.normal(size=(ks, q)), rng.normal(size=(kt, q))
    ev_S, ev_T = np.sort(rng.uniform(0, 50, ks)), np.sort(rng.uniform(0, 50, kt))
    fast = fmaps.fit_functional_map(A_S, A_T, ev_S, ev_T, w_orient=0.0)
    full = fmaps.fit_functional_map(A_S, A_T, ev_S, ev_T, np.zeros((1, ks, ks)), np.zeros((1, kt, kt)), w_orient=1.0)
    assert fast.shape == (ks, kt) and np.allclose(fast, full, atol=1e-10)


def test_zoomout_matches_samples_first_and_every_vertex_in_the_last_iterations(ellipsoid, monkeypatch):
    V, F = ellipsoid
    B = mesh_basis(V, F, k=30, n_samples=100)
    seen = []
    real = zoomout.p2p_from_fmap

    def spy(C, rows, cands, adjoint=True, cells=None):
        seen.append(len(cands))
        assert (cells is not None) == (len(cands) == B.n)      # the all-vertex searches go by cells
        return real(C, rows, cands, adjoint=adjoint, cells=cells)

    monkeypatch.setattr(zoomout, "p2p_from_fmap", spy)
    C = zoomout.zoomout(B, B, np.eye(10), k_end=30, step=5, all_target_vertices=True)   # k = 10, 15, 20, 25
    assert seen == [100, 100, 100, B.n]                  # default full_band=0.1: k >= 27, at least the last one
    assert np.allclose(np.abs(np.diag(C)), 1.0, atol=1e-6)   # self-map: the identity stays the identity
    seen.clear()
    zoomout.zoomout(B, B, np.eye(10), k_end=30, step=5, all_target_vertices=True, full_band=0.5)   # k >= 15
    assert seen == [100, B.n, B.n, B.n]
    seen.clear()
    zoomout.zoomout(B, B, np.eye(10), k_end=30, step=5, all_target_vertices=True, full_band=1.0)
    assert seen == [B.n] * 4
    seen.clear()
    zoomout.zoomout(B, B, np.eye(10), k_end=30, step=5, all_target_vertices=False)
    assert seen == [100] * 4


def test_bench_prints_each_project_method_over_each_pyfm_mode():
    from bench.correspondence import time_ratio_lines, time_ratios

    summary = {"pyfm_none": {"seconds": 18.0}, "pyfm_5pts": {"seconds": 24.0},
               "dense_sparse": {"seconds": 6.0}, "dense_auto": {"seconds": 9.0}}
    ratios = time_ratios(summary)
    assert ratios == {("dense_sparse", "pyfm_none"): 6 / 18, ("dense_sparse", "pyfm_5pts"): 0.25,
                      ("dense_auto", "pyfm_none"): 0.5, ("dense_auto", "pyfm_5pts"): 9 / 24}
    lines = time_ratio_lines(summary)
    assert "dense_auto / pyfm_none: 0.500  (above 1/3)" in "\n".join(lines)
    assert time_ratio_lines({"dense_sparse": {"seconds": 1.0}}) == []


def test_point_distances_are_the_solved_rows_kept_once(ellipsoid, monkeypatch):
    """``point_distances`` gives ``distances``' rows bit for bit (in the order asked, repeats included), solves each
    vertex once, keeps them read-only, and past ``MAX_KEPT_DISTANCE_ROWS`` still answers right without keeping."""
    B = mesh_basis(*ellipsoid, k=8, n_samples=50)
    want = B.distances([7, 3, 7, 11])
    solved = []
    plain = B.distances
    monkeypatch.setattr(B, "distances", lambda s: (solved.extend(np.atleast_1d(s).tolist()), plain(s))[1])
    assert np.array_equal(B.point_distances([7, 3, 7, 11]), want)
    assert np.array_equal(B.point_distances([11, 3]), want[[3, 1]])
    assert sorted(solved) == [3, 7, 11]                        # each vertex solved once, repeats and reuse included
    assert not B._derived["point_distance_rows"][3].flags.writeable
    monkeypatch.setattr(dense_basis, "MAX_KEPT_DISTANCE_ROWS", 4)
    assert np.array_equal(B.point_distances([20, 21, 7]), plain([20, 21, 7]))
    assert len(B._derived["point_distance_rows"]) == 4


def test_kept_distance_rows_travel_with_the_basis_arrays(ellipsoid, monkeypatch):
    """``to_arrays`` carries the kept rows and ``from_arrays`` serves them without solving again."""
    B = mesh_basis(*ellipsoid, k=8, n_samples=50)
    rows = B.point_distances([5, 9])
    back = dense_basis.MeshBasis.from_arrays(B.to_arrays())
    monkeypatch.setattr(back, "distances", lambda s: pytest.fail(f"solved {s} again"))
    assert np.array_equal(back.point_distances([9, 5]), rows[::-1])
    assert "point_distance_ids" not in mesh_basis(*ellipsoid, k=8, n_samples=50).to_arrays()


def test_face_gradients_from_the_kept_frames_are_the_plain_formula(ellipsoid):
    """The gradient of vertex values from ``MeshBasis.face_frames`` equals the per-face formula sum_c f_c (n x e_c)
    / (2 A), bit for bit, and the gradient of a linear function is that function's direction in the face plane."""
    from corr_core.correspondence.dense.basis import face_gradients
    from corr_core.geometry.primitives import face_normals

    B = mesh_basis(*ellipsoid, k=8, n_samples=50)
    V, F = B.V, B.F
    f = np.stack([V @ np.array([1.0, -2.0, 0.5]), np.sin(3 * V[:, 0])], axis=1)
    N = face_normals(V, F)
    twice_area = 2.0 * face_areas(V, F)
    plain = np.zeros((len(F), 3, 2))
    for c in range(3):
        w = np.cross(N, V[F[:, (c + 2) % 3]] - V[F[:, (c + 1) % 3]]) / np.maximum(twice_area, 1e-300)[:, None]
        plain += w[:, :, None] * f[F[:, c]][:, None, :]
    assert np.array_equal(face_gradients(B, f), plain)
    g = np.array([1.0, -2.0, 0.5])
    in_plane = g - (N @ g)[:, None] * N
    assert np.allclose(face_gradients(B, f)[:, :, 0], in_plane, atol=1e-9)
    assert face_gradients(B, f[:, :1]).shape == (len(F), 3, 1)


def test_kept_point_features_are_point_features_once_per_points(ellipsoid, monkeypatch):
    """A template's point features are computed once per points and weight, read-only, equal to ``point_features``;
    past ``MAX_KEPT_FEATURE_SETS`` they are computed each time."""
    from corr_core.correspondence.dense import init

    B = mesh_basis(*ellipsoid, k=8, n_samples=50)
    points = B.samples[:4]
    want = init.point_features(mesh_basis(*ellipsoid, k=8, n_samples=50), points)
    first = init.kept_point_features(B, points)
    assert np.array_equal(first, want) and not first.flags.writeable
    assert init.kept_point_features(B, points) is first
    assert not np.array_equal(init.kept_point_features(B, points, chirality_weight=0.5), first)
    assert not np.array_equal(init.kept_point_features(B, points[::-1]), first)
    monkeypatch.setattr(init, "MAX_KEPT_FEATURE_SETS", 3)
    extra = init.kept_point_features(B, B.samples[4:7])
    assert np.array_equal(extra, init.point_features(B, B.samples[4:7]))
    assert init.kept_point_features(B, B.samples[4:7]) is not extra
