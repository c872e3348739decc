"""The dense-map building blocks on small meshes with known answers: measures, transfer, functional maps,
ZoomOut, feature points, assignment ranking, orientation agreement."""
from __future__ import annotations

import numpy as np
import pytest

from corr_core.correspondence.dense import fmaps, init, measures, mesh_basis, transfer_landmarks, zoomout
from corr_core.geometry.geodesic import GeodesicSolver
from corr_core.geometry.primitives import face_areas
from tests.helpers import sphere


@pytest.fixture(scope="module")
def ellipsoid():
    """An ellipsoid with three different radii (no intrinsic symmetry besides mirrors)."""
    V, F = sphere(n=800)
    V = V * np.array([1.0, 0.6, 0.35])
    return V, F, mesh_basis(V, F, k=30, n_samples=300)


def test_dense_errors_of_identity_are_zero_and_of_a_shift_equal_the_geodesic(ellipsoid):
    V, F, B = ellipsoid
    truth = np.arange(len(V))
    shifted = truth.copy()
    shifted[5] = 17
    errs = measures.dense_errors(V, F, {"id": truth, "shift": shifted}, truth, vertices=np.array([5, 6]))
    assert np.all(errs["id"] == 0.0)
    expected = GeodesicSolver(V, F).distance(5)[17] / np.sqrt(face_areas(V, F).sum())   # the mesh's own unit
    assert errs["shift"][0] == pytest.approx(expected) and errs["shift"][1] == 0.0
    with pytest.raises(ValueError, match="entries"):
        measures.dense_errors(V, F, {"short": truth[:-1]}, truth)


def test_kim_curve_and_summary():
    e = np.array([0.0, 0.02, 0.06, 0.2, 0.3])
    curve = measures.kim_curve(e, thresholds=np.array([0.0, 0.05, 0.1, 0.25]))
    assert curve.tolist() == [0.2, 0.4, 0.6, 0.8]
    s = measures.summary(e)
    assert s["within_0.05"] == 0.4 and s["within_0.10"] == 0.6 and s["within_0.25"] == 0.8
    assert s["mean_error"] == pytest.approx(e.mean())


def test_landmark_transfer_and_accuracy(ellipsoid):
    V, F, _ = ellipsoid
    p2p = np.arange(len(V))[::-1].copy()
    lm = np.array([0, 10, 20])
    placed = transfer_landmarks(p2p, lm)
    assert placed.tolist() == [len(V) - 1, len(V) - 11, len(V) - 21]
    errors, nearest = measures.landmark_errors(V, F, lm, lm)                 # perfect placement
    assert np.all(errors == 0) and measures.landmark_accuracy(nearest) == 1.0
    _, nearest = measures.landmark_errors(V, F, lm[[1, 0, 2]], lm)           # two names swapped
    assert measures.landmark_accuracy(nearest) == pytest.approx(1 / 3)
    with pytest.raises(ValueError, match="outside"):
        transfer_landmarks(p2p, [len(V)])


def test_functional_map_of_the_identity_recovers_the_identity(ellipsoid):
    V, F, B = ellipsoid
    C = fmaps.fmap_from_p2p(np.arange(len(V)), B.evecs[:, :20], B.evecs[:, :20])
    assert np.allclose(C, np.eye(20), atol=1e-8)
    assert np.array_equal(zoomout.p2p_full(B, B, C), np.arange(len(V)))


def test_fit_from_point_features_and_zoomout_map_a_rotated_copy(ellipsoid):
    V, F, B = ellipsoid
    c, s = np.cos(1.0), np.sin(1.0)
    Vr = V @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
    Br = mesh_basis(Vr, F, k=30, n_samples=300)
    pts = init.extremities(B, max_points=6)
    C, p2p_samples = init.map_from_points(B, Br, pts, pts, k_init=15, k_end=30)
    err = np.linalg.norm(Vr[p2p_samples] - Vr[B.samples], axis=1).mean()
    assert err < 0.05


def test_extremities_of_an_ellipsoid_are_the_ends_of_its_long_axis(ellipsoid):
    V, F, B = ellipsoid
    pts = init.extremities(B, max_points=6)
    assert len(pts) >= 2
    assert np.all(np.abs(V[pts[:2], 0]) > 0.9)                # the two tips at x = +-1
    assert V[pts[0], 0] * V[pts[1], 0] < 0


def test_ranked_assignments_put_the_true_assignment_first():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(5, 3))
    D = np.linalg.norm(X[:, None] - X[None], axis=2)
    perm = np.array([3, 0, 4, 1, 2])                           # target point perm[i] is source point i
    Dt = np.empty_like(D)
    Dt[np.ix_(perm, perm)] = D
    s, t, cost = init.ranked_assignments(D, Dt, keep=3)[0]
    assert cost == pytest.approx(0.0) and np.array_equal(t[s], perm)
    with pytest.raises(ValueError, match="at least 3"):
        init.ranked_assignments(D[:2, :2], Dt)


def test_orientation_agreement_separates_a_map_from_its_mirror(ellipsoid):
    V, F, B = ellipsoid
    Vm, Fm = V * np.array([1.0, -1.0, 1.0]), F[:, ::-1].copy()
    Bm = mesh_basis(Vm, Fm, k=10, n_samples=10)
    identity = B.samples                                       # vertex i -> i: orientation-reversing here
    assert init.orientation_agreement(B, B, identity) > 0.9
    assert init.orientation_agreement(B, Bm, identity) < -0.9


def test_chirality_functions_change_sign_on_the_mirror_image(ellipsoid):
    V, F, B = ellipsoid
    Vm, Fm = V * np.array([1.0, -1.0, 1.0]), F[:, ::-1].copy()
    Bm = mesh_basis(Vm, Fm, k=10, n_samples=10)
    pts = np.array([0, 100, 400])
    cs = fmaps.chirality_functions(B, B.distances(pts).T)
    cm = fmaps.chirality_functions(Bm, Bm.distances(pts).T)
    assert np.allclose(cs, -cm, atol=1e-8)
    assert np.abs(cs).max() > 0.5


def test_orientation_term_prefers_the_orientation_preserving_map(ellipsoid):
    """With descriptors that the mirror y -> -y keeps, only the orientation term tells the mirror map apart."""
    V, F, B = ellipsoid
    k = 15
    f = np.c_[V[:, 0], V[:, 2] + V[:, 0] ** 2, V[:, 1] ** 2]
    Om = fmaps.orientation_operators(B, f, k)
    C_id = np.eye(k)
    partner = np.argmin(np.linalg.norm(V[None, :, :] - (V * np.array([1, -1, 1]))[:, None, :], axis=2), axis=1)
    C_mirror = fmaps.fmap_from_p2p(partner, B.evecs[:, :k], B.evecs[:, :k])
    energy = lambda C: sum(np.sum((C @ Om[i] - Om[i] @ C) ** 2) for i in range(len(Om)))
    assert energy(C_id) < 1e-12
    assert energy(C_mirror) > 0.1 * float(np.sum(Om**2))


def test_adjoint_point_map_of_an_orthogonal_map_equals_the_direct_one(ellipsoid):
    _, _, B = ellipsoid
    rng = np.random.default_rng(0)
    Q, _ = np.linalg.qr(rng.normal(size=(12, 12)))
    rows = B.evecs[:50, :12]
    direct = fmaps.p2p_from_fmap(Q, rows, B.evecs[:, :12], adjoint=False)
    assert np.array_equal(fmaps.p2p_from_fmap(Q, rows, B.evecs[:, :12], adjoint=True), direct)
    assert np.array_equal(direct, fmaps.nearest_rows(rows @ Q, B.evecs[:, :12]))


def test_refine_spectral_undoes_a_one_ring_scramble(ellipsoid):
    from corr_core.correspondence.dense import refine_spectral
    from corr_core.geometry.primitives import vertex_adjacency

    V, F, B = ellipsoid
    A = vertex_adjacency(F, len(V)).tocsr()
    rng = np.random.default_rng(1)
    scrambled = np.array([rng.choice(A.indices[A.indptr[i]:A.indptr[i + 1]]) if rng.random() < 0.5 else i
                          for i in range(len(V))])
    fixed = refine_spectral(B, B, scrambled, iterations=5, n_candidates=16)
    assert np.mean(fixed == np.arange(len(V))) > 0.95 > np.mean(scrambled == np.arange(len(V)))
