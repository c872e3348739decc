"""Tests for corr_core.correspondence.mobius (Möbius maps and Möbius voting)."""

import numpy as np
import pytest

from corr_core.correspondence.mobius import (apply_mobius, compose_mobius, dense_map, extend_landmarks, fit_mobius,
                              invert_mobius, mobius_derivative_abs, mobius_from_triplets,
                              mobius_to_canonical, mobius_vote_landmarks, mutually_closest_pairs, ROOTS3,
                              score_maps)

from tests.helpers import COURSE_DATA

SCAPE = COURSE_DATA / "scape"


def crandn(rng, *shape):
    return rng.normal(size=shape) + 1j * rng.normal(size=shape)


def test_triplet_map_reproduces_a_known_map():
    rng = np.random.default_rng(0)
    c = crandn(rng, 4)
    z = crandn(rng, 50)
    w = (c[0] * z + c[1]) / (c[2] * z + c[3])
    got = mobius_from_triplets(z[:3], w[:3])
    np.testing.assert_allclose(apply_mobius(got, z), w, rtol=1e-9, atol=1e-9)
    a, b, cc, d = got
    assert abs(a * d - b * cc - 1) < 1e-12
    # batched, and the canonical frame sends triplets to the cube roots of unity
    trip = crandn(rng, 7, 3)
    m = mobius_to_canonical(trip)
    assert m.shape == (7, 4)
    for t in range(7):
        np.testing.assert_allclose(apply_mobius(m[t], trip[t]), ROOTS3, atol=1e-9)


def test_infinity_compose_invert_derivative():
    c = np.array([2.0, 1.0, 1.0, -1.0], dtype=complex)           # f(z) = (2z + 1) / (z - 1)
    out = apply_mobius(c, np.array([1.0, np.inf, 0.0]))
    assert np.isinf(out[0]) and out[1] == 2 and out[2] == -1
    rng = np.random.default_rng(1)
    z = crandn(rng, 20)
    g = crandn(rng, 4)
    np.testing.assert_allclose(apply_mobius(compose_mobius(g, c), z), apply_mobius(g, apply_mobius(c, z)),
                               rtol=1e-9)
    np.testing.assert_allclose(apply_mobius(invert_mobius(c), apply_mobius(c, z)), z, rtol=1e-9)
    h = 1e-6
    numeric = np.abs(apply_mobius(c, z + h) - apply_mobius(c, z)) / h
    np.testing.assert_allclose(mobius_derivative_abs(c, z), numeric, rtol=1e-4)


def test_fit_mobius_recovers_map_from_noisy_points():
    rng = np.random.default_rng(2)
    c = crandn(rng, 4)
    z = crandn(rng, 300)
    w = apply_mobius(c, z)
    got = fit_mobius(z, w + 1e-6 * crandn(rng, 300))
    assert np.max(np.abs(apply_mobius(got, z) - w)) < 1e-4


def test_mutually_closest_pairs_matches_brute_force():
    rng = np.random.default_rng(3)
    A, B = crandn(rng, 40), crandn(rng, 30)
    pairs, dist = mutually_closest_pairs(A, B)
    D = np.abs(A[:, None] - B[None])
    ref = [(i, j) for i in range(40) for j in range(30) if D[i].argmin() == j and D[:, j].argmin() == i]
    assert [tuple(p) for p in pairs] == ref
    np.testing.assert_allclose(dist, [D[i, j] for i, j in ref])


def synthetic_pair(rng, n_samples=80, n_landmarks=5, noise=0.0):
    """Source points in the plane; target = known Möbius image, shuffled, optionally noisy."""
    Zs = 0.8 * crandn(rng, n_samples)
    Ls = 0.8 * crandn(rng, n_landmarks)
    m = np.array([1.0 + 0.3j, 0.2, 0.1 - 0.2j, 1.1])
    perm_s, perm_l = rng.permutation(n_samples), rng.permutation(n_landmarks)
    Zt = apply_mobius(m, Zs)[perm_s] + noise * crandn(rng, n_samples)
    Lt = apply_mobius(m, Ls)[perm_l]
    return Zs, Zt, Ls, Lt, perm_s, perm_l, m


def test_voting_recovers_landmark_permutation_and_dense_map():
    rng = np.random.default_rng(4)
    Zs, Zt, Ls, Lt, perm_s, perm_l, m = synthetic_pair(rng)
    out = mobius_vote_landmarks(Zs, Zt, Ls, Lt, K=0.05)
    truth = np.argsort(perm_l)                       # target index of each source landmark
    np.testing.assert_array_equal(out["pred"], truth)
    assert out["best_maps"][0]["score"] == pytest.approx(1.0)
    np.testing.assert_allclose(apply_mobius(out["best_maps"][0]["coeffs"], Ls), Lt[truth], atol=1e-8)
    assert out["votes"].shape == (5, 5)
    np.testing.assert_array_equal(dense_map(out["best_maps"][0], Zs, Zt), np.argsort(perm_s))
    # extension: 20 landmarks carried by the consensus maps
    L20 = 0.8 * crandn(rng, 20)
    p20 = rng.permutation(20)
    T20 = apply_mobius(m, L20)[p20]
    np.testing.assert_array_equal(extend_landmarks(out["consensus_maps"], L20, T20), np.argsort(p20))


def test_voting_surface_metric_with_noise():
    """Noisy target samples; the 'surface' metric with the known scale |m'| still finds the permutation."""
    rng = np.random.default_rng(5)
    Zs, Zt, Ls, Lt, perm_s, perm_l, m = synthetic_pair(rng, n_samples=100, noise=0.01)
    lam_s = np.full(len(Zs), 0.05)                   # planar length per unit of K
    lam_t = 0.05 * mobius_derivative_abs(m, Zs)[perm_s]
    lam_ls = np.full(len(Ls), 0.05)
    lam_lt = 0.05 * mobius_derivative_abs(m, Ls)[perm_l]
    out = mobius_vote_landmarks(Zs, Zt, Ls, Lt, K=0.5, metric="surface", lam_samples=(lam_s, lam_t),
                                lam_landmarks=(lam_ls, lam_lt), power=4)
    np.testing.assert_array_equal(out["pred"], np.argsort(perm_l))


@pytest.mark.course
def test_scape_two_meshes_voting():
    if not SCAPE.is_dir():
        pytest.skip(f"course data not found at {SCAPE}")
    from corr_core.geometry.mesh_io import load_mesh
    from corr_core.geometry.midedge import edge_midpoints, midedge_conformal_factor, midedge_flatten, vertex_to_edge
    from corr_core.geometry.sampling import farthest_point_samples

    sparse = np.loadtxt(SCAPE / "sparse_landmark_vids.txt", delimiter=",", usecols=0, dtype=int)
    full = np.loadtxt(SCAPE / "landmark_vids.txt", delimiter=",", usecols=0, dtype=int)
    n = 300
    flat = []
    for path in [SCAPE / "meshes/template/mesh000.obj", SCAPE / "meshes/test/mesh002.obj"]:
        V, F = load_mesh(path)
        Z, E, FE, kept = midedge_flatten(V, F)      # default (index-free) cut
        M = edge_midpoints(V, E)
        S = farthest_point_samples(M, n, start=int(np.argmax(np.linalg.norm(M - M.mean(0), axis=1))))
        area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
        lam = midedge_conformal_factor(V, E, FE, kept, Z, F) * np.sqrt(area / n)
        flat.append((Z, E, S, lam))
    (Zs, Es, Ss, ls), (Zt, Et, St, lt) = flat
    es, et = vertex_to_edge(sparse, Es), vertex_to_edge(sparse, Et)
    out = mobius_vote_landmarks(Zs[Ss], Zt[St], Zs[es], Zt[et], K=0.5, metric="surface",
                                lam_samples=(ls[Ss], lt[St]), lam_landmarks=(ls[es], lt[et]), power=4, K_scale=0.3)
    np.testing.assert_array_equal(out["pred"], np.arange(5))        # ground truth: vertex i <-> vertex i
    ext = extend_landmarks(out["consensus_maps"], Zs[vertex_to_edge(full, Es)], Zt[vertex_to_edge(full, Et)],
                           top=100)
    assert np.mean(ext == np.arange(20)) >= 0.9                      # measured 1.0


def test_score_maps_gives_the_same_scores_whatever_the_block_size():
    rng = np.random.default_rng(3)
    ms, mt = (rng.standard_normal((13, 4)) + 1j * rng.standard_normal((13, 4)) for _ in range(2))
    Zs, Zt = (rng.standard_normal(40) + 1j * rng.standard_normal(40) for _ in range(2))
    lam_s, lam_t = rng.random(40) + 0.5, rng.random(40) + 0.5
    scores = [score_maps(ms, mt, Zs, Zt, K=0.8, metric="surface", lam_s=lam_s, lam_t=lam_t, K_scale=0.7,
                                chunk=c) for c in (1, 4, 5, 256)]
    assert scores[0].max() > 0 and all(np.array_equal(s, scores[0]) for s in scores[1:])
