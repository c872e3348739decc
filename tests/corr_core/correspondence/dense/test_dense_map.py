"""End-to-end dense maps on a small generated humanoid: a posed copy, a rigidly moved copy, the mirror image, a
remeshed pose, determinism.

The humanoid is exactly left/right symmetric, so only orientation can tell left from right. Its torso is also
nearly front/back symmetric, which makes the 180-degree turn (left<->right *and* front<->back, orientation
preserving) almost an isometry; a belly bump (``_with_belly``, symmetric in x) makes the front recognisable, as
on a real body."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from corr_core.correspondence.dense import dense_map, measures, mesh_basis, transfer_landmarks
from corr_core.generate import humanoid
from corr_core.generate.defects import cut_along_a_seam, with_fins
from corr_core.geometry.primitives import surface_area

K, K_INIT, N_SAMPLES = 40, 20, 600
FAST = {"extrinsic": {"n_patches": 120, "rounds": 4}}


def _with_belly(V, F, height: float = 0.06):
    """Push the front of the torso out along the normals (a bump centred at x = 0; keeps left/right symmetry)."""
    from corr_core.geometry.primitives import vertex_normals

    centre = np.array([0.0, 1.15, 0.09])
    bump = height * np.exp(-np.sum((V - centre) ** 2, axis=1) / (2 * 0.08**2))
    return V + bump[:, None] * vertex_normals(V, F)


def _basis(V, F):
    return mesh_basis(V, F, k=K, n_samples=N_SAMPLES)


@pytest.fixture(scope="module")
def body():
    V, F = humanoid.make_humanoid_rest(grid_step=0.045)
    V = _with_belly(V, F)
    W, _ = humanoid.skinning_weights(V, F)
    pose = humanoid.random_pose(np.random.default_rng(3))
    Vp = humanoid.pose_mesh(V, W, pose)
    lms = humanoid.landmark_vertices(V)
    return {"V": V, "F": F, "W": W, "pose": pose, "Vp": Vp, "S": _basis(V, F), "T": _basis(Vp, F),
            "landmarks": np.array([lms[n] for n in humanoid.LANDMARK_NAMES]),
            "sparse": np.array([lms[n] for n in humanoid.SPARSE_LANDMARK_NAMES])}


@pytest.fixture(scope="module")
def pose_maps(body):
    """The maps of the posed copy as it is, automatic (``"auto"``) and from the 5 points (``"sparse"``): the
    reference of the tests that change the target and expect the same map, made once for them all."""
    maps = {"auto": _run(body, body["Vp"], body["F"], body["T"]),
            "sparse": _run(body, body["Vp"], body["F"], body["T"], sparse_target=body["sparse"])}
    for p2p in maps.values():
        p2p.setflags(write=False)                  # shared: a test that changed one would change the others'
    return maps


def _mode(sparse) -> str:
    return "auto" if sparse is None else "sparse"


def _run(body, V_t, F_t, B_t, sparse_target=None, **kw):
    lm = {} if sparse_target is None else {"landmarks_template": body["sparse"], "landmarks_target": sparse_target}
    return dense_map(body["V"], body["F"], V_t, F_t, basis_template=body["S"], basis_target=B_t, k=K,
                     k_init=K_INIT, refine_options=FAST, **lm, **kw)


def _mean_error(V_t, F_t, p2p, truth):
    return float(measures.dense_errors(V_t, F_t, {"m": p2p}, truth)["m"].mean())


def _sides_kept(body, V_t, F_t, p2p, truth) -> bool:
    """Every transferred "Left X" / "Right X" landmark is nearer its own true landmark than its mirror twin's."""
    names = list(humanoid.LANDMARK_NAMES)
    placed = transfer_landmarks(p2p, body["landmarks"])
    errors, _ = measures.landmark_errors(V_t, F_t, placed, truth[body["landmarks"]])
    twin_ids = [names.index(n.replace("Left", "Right")) if n.startswith("Left") else
                names.index(n.replace("Right", "Left")) for n in names if n.startswith(("Left", "Right"))]
    own_ids = [i for i, n in enumerate(names) if n.startswith(("Left", "Right"))]
    to_twin, _ = measures.landmark_errors(V_t, F_t, placed[own_ids], truth[body["landmarks"][twin_ids]])
    return bool(np.all(errors[own_ids] < to_twin))


def test_sparse_map_to_a_pose_is_near_identity_and_refinement_helps(body, pose_maps):
    truth = np.arange(len(body["V"]))
    refined = pose_maps["sparse"]
    spectral = _run(body, body["Vp"], body["F"], body["T"], sparse_target=body["sparse"], refine=None)
    e_ref = _mean_error(body["Vp"], body["F"], refined, truth)
    e_spec = _mean_error(body["Vp"], body["F"], spectral, truth)
    assert refined.shape == (len(body["V"]),) and refined.dtype == np.int64
    assert e_ref < 0.02, e_ref
    assert e_ref < e_spec
    assert _sides_kept(body, body["Vp"], body["F"], refined, truth)


def test_an_alternative_map_replaces_the_points_map_only_when_it_keeps_the_points_and_is_less_distorted(
        body, pose_maps):
    """Sparse mode with ``alternative``: the true map (undistorted, keeps the points) wins over the map made from
    the points; the mirror map (as undistorted on this exactly symmetric body, but it swaps the left and right
    points) does not; an alternative without points is refused."""
    truth = np.arange(len(body["V"]))
    mirror = cKDTree(body["V"]).query(body["V"] * [-1, 1, 1])[1]         # vertex i -> its left/right twin
    from_points = pose_maps["sparse"]
    assert not np.array_equal(from_points, truth)
    assert np.array_equal(_run(body, body["Vp"], body["F"], body["T"], sparse_target=body["sparse"],
                               alternative=truth), truth)
    assert np.array_equal(_run(body, body["Vp"], body["F"], body["T"], sparse_target=body["sparse"],
                               alternative=mirror), from_points)
    with pytest.raises(ValueError, match="alternative: only with landmarks"):
        _run(body, body["Vp"], body["F"], body["T"], alternative=truth)
    with pytest.raises(ValueError, match="alternative must be a dense map of this pair"):
        _run(body, body["Vp"], body["F"], body["T"], sparse_target=body["sparse"], alternative=truth[:5])


def test_automatic_map_to_a_rigidly_moved_pose_keeps_left_and_right(body):
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    Vm = body["Vp"] @ R.T + np.array([0.3, -0.2, 1.0])
    p2p = _run(body, Vm, body["F"], _basis(Vm, body["F"]))
    truth = np.arange(len(body["V"]))
    assert _mean_error(Vm, body["F"], p2p, truth) < 0.03
    assert _sides_kept(body, Vm, body["F"], p2p, truth)          # a left/right flip fails this


def test_a_target_in_other_units_gets_the_map_of_the_target_as_it_is(body, pose_maps):
    """The target x1024 (exact): the same maps, bit for bit, in both modes. In millimetres (x1000) or kilometres
    (x0.001) and far from the origin: maps as good as the target's as it is. Without ``size_exponent`` /
    ``in_units_of`` the rigid patch fits, the ARAP registration, the functional map's Laplacian term and the
    eigensolver saw a target 1000 times the template's size, and those maps were wrong almost everywhere."""
    truth = np.arange(len(body["V"]))
    for sparse in (None, body["sparse"]):
        as_is = pose_maps[_mode(sparse)]
        V = body["Vp"] * 1024.0
        assert np.array_equal(_run(body, V, body["F"], _basis(V, body["F"]), sparse_target=sparse), as_is)
        error = _mean_error(body["Vp"], body["F"], as_is, truth)
        for factor in (1000.0, 0.001):
            V = body["Vp"] * factor + 5000.0
            moved = _run(body, V, body["F"], _basis(V, body["F"]), sparse_target=sparse)
            assert _mean_error(V, body["F"], moved, truth) < 1.25 * error + 0.002, (factor, sparse is None)


def test_a_person_of_another_size_gets_the_map_of_the_same_person_at_the_template_size(body):
    """The target 1.41 and 0.78 times as tall (no power of two rounds that away; ``basis.in_size_of``): in both
    modes almost every vertex maps as with the target at the template's size, and the errors match. Measured
    in its own size, the functional map's Laplacian term, the rigid patch fits and the ARAP registration saw a
    person of another size and mapped a fifth to a half of the vertices elsewhere (the course pose mesh002 at
    x1.41: mean error 0.0145 against 0.0088, ``python bench/dense_units.py``). The reference is the pose scaled to
    exactly the template's area: the pose at its own size is inside ``SIZE_DEAD_ZONE``, so it is not rescaled, and a
    length change of a percent already moves a few percent of the vertices (point-to-plane ICP: 3 %)."""
    truth = np.arange(len(body["V"]))
    to_template_area = np.sqrt(surface_area(body["V"], body["F"]) / surface_area(body["Vp"], body["F"]))
    V_ref = body["Vp"] * to_template_area
    for sparse in (None, body["sparse"]):
        as_is = _run(body, V_ref, body["F"], _basis(V_ref, body["F"]), sparse_target=sparse)
        error = _mean_error(V_ref, body["F"], as_is, truth)
        for factor in (1.41, 0.78):
            V = body["Vp"] * factor
            sized = _run(body, V, body["F"], _basis(V, body["F"]), sparse_target=sparse)
            assert np.mean(sized == as_is) > 0.95, (factor, sparse is None, np.mean(sized == as_is))
            assert _mean_error(V, body["F"], sized, truth) < 1.05 * error + 0.0005, (factor, sparse is None)


def test_in_size_of_scales_to_the_template_area_outside_its_dead_zone(body):
    from corr_core.correspondence.dense.basis import SIZE_DEAD_ZONE, in_size_of

    S, T = body["S"], body["T"]
    assert in_size_of(T, S) is T                                                 # one body in two poses
    near = T.scaled(2.0 ** (0.9 * SIZE_DEAD_ZONE))
    assert in_size_of(near, S) is near                                           # within the dead zone: as it is
    tall = T.scaled(1.3)
    sized = in_size_of(tall, S)
    assert sized is in_size_of(tall, S)                                          # made once
    np.testing.assert_allclose(sized.area, S.area, rtol=1e-12)
    np.testing.assert_allclose(sized.V, tall.V * np.sqrt(S.area / tall.area), rtol=1e-12)
    assert in_size_of(sized, S) is sized                                         # idempotent
    mm = T.scaled(1300.0)                                                        # other units and another size
    np.testing.assert_allclose(in_size_of(mm, S).area, S.area, rtol=1e-12)


def test_a_target_with_inward_faces_gets_the_map_of_the_target_as_it_is_and_a_warning(body, pose_maps):
    """Reversed faces would swap left and right (orientation decides the chirality): the basis turns them outward,
    says so, and both modes give the map of the target as it is, bit for bit."""
    inward = np.ascontiguousarray(body["F"][:, ::-1])
    with pytest.warns(UserWarning, match="faces point inward"):
        B = _basis(body["Vp"], inward)
    for sparse in (None, body["sparse"]):
        assert np.array_equal(_run(body, body["Vp"], inward, B, sparse_target=sparse), pose_maps[_mode(sparse)])


def _cut_along_a_seam(V, F):
    """``defects.cut_along_a_seam`` of the faces in front (centroid z above the median): a front and a back piece."""
    centroid_z = V[F].mean(axis=1)[:, 2]
    return cut_along_a_seam(V, F, centroid_z > np.median(centroid_z))


def test_a_mesh_cut_along_a_seam_gets_the_map_of_the_welded_mesh(body, pose_maps):
    """Seam vertices repeated with new ids cut the body into a front and a back piece; the basis welds them
    (``repair.coincident_representatives``): a cut target gets the map of the whole target, bit for bit, in both
    modes (a point given on a copy is its original), and on a cut template every copy takes its original's image.
    Without the weld only the larger piece was mapped (the course pose mesh002 cut so: mean error 0.2877 at
    5eda5db, ``python bench/dense_units.py``, last line)."""
    V, F, shared, copies = _cut_along_a_seam(body["Vp"], body["F"])
    assert len(shared) > 20
    B = _basis(V, F)
    assert B.n == body["T"].n
    for sparse in (None, body["sparse"]):
        assert np.array_equal(_run(body, V, F, B, sparse_target=sparse), pose_maps[_mode(sparse)])
    assert np.array_equal(B.to_local(copies), B.to_local(shared))              # a point given on a copy
    Vs, Fs, shared_s, copies_s = _cut_along_a_seam(body["V"], body["F"])
    p2p = dense_map(Vs, Fs, body["Vp"], body["F"], k=K, k_init=K_INIT, refine_options=FAST,
                    basis_template=_basis(Vs, Fs), basis_target=body["T"])
    assert np.array_equal(p2p[:len(body["V"])], pose_maps["auto"])
    assert np.array_equal(p2p[copies_s], p2p[shared_s])


def test_a_target_with_fins_gets_the_map_of_the_target_without_them(body, pose_maps):
    """Triangles standing on 30 edges of the target (non-manifold edges, each with a new apex vertex) are left out
    of its basis (``primitives.without_fins``): the map is the clean target's, bit for bit (on the course pose
    mesh002 with 30 fins two edges tall it was 0.886 the same before, ``python bench/dense_units.py``, last line)."""
    V, F = with_fins(body["Vp"], body["F"], 30)
    B = _basis(V, F)
    assert B.n == body["T"].n
    for sparse in (None, body["sparse"]):
        assert np.array_equal(_run(body, V, F, B, sparse_target=sparse), pose_maps[_mode(sparse)])


def test_in_units_of_scales_by_a_power_of_two_and_leaves_comparable_sizes_alone(body):
    from corr_core.correspondence.dense.basis import in_units_of, units_exponent

    S, T = body["S"], body["T"]
    assert units_exponent(S, T) == 0 and in_units_of(T, S) is T                # comparable sizes: untouched
    big = T.scaled(1000.0)
    assert units_exponent(S, big) == -10                                         # 1000 -> 1/1024
    back = in_units_of(big, S)
    assert back is in_units_of(big, S)                                           # made once
    np.testing.assert_array_equal(back.V, big.V / 1024.0)
    np.testing.assert_allclose(back.area, T.area * (1000.0 / 1024.0) ** 2)
    np.testing.assert_allclose(back.evals[1:], T.evals[1:] * (1024.0 / 1000.0) ** 2)
    M = back.evecs.T @ (back.mass[:, None] * back.evecs)
    np.testing.assert_allclose(M, np.eye(M.shape[0]), atol=1e-8)                 # still M-orthonormal


def test_automatic_map_to_the_mirror_image_is_orientation_preserving(body):
    """The mirror image (x -> -x, faces reversed) of a pose is another pose of the same symmetric body; the
    orientation-preserving truth sends vertex i to its mirror partner, the identity would reverse orientation."""
    Vm, Fm = body["Vp"] * np.array([-1.0, 1.0, 1.0]), body["F"][:, ::-1].copy()
    partner = humanoid.mirror_pairs(body["V"])
    assert partner is not None
    p2p = _run(body, Vm, Fm, _basis(Vm, Fm))
    assert _mean_error(Vm, Fm, p2p, partner) < 0.03
    assert _mean_error(Vm, Fm, p2p, np.arange(len(body["V"]))) > 0.2


def test_different_connectivity_end_to_end(body):
    """Target: the same body meshed on a finer grid and posed alike; truth: nearest vertex at rest."""
    V2, F2 = humanoid.make_humanoid_rest(grid_step=0.04)
    V2 = _with_belly(V2, F2)
    W2, _ = humanoid.skinning_weights(V2, F2)
    Vp2 = humanoid.pose_mesh(V2, W2, body["pose"])
    assert len(V2) != len(body["V"])
    truth = cKDTree(V2).query(body["V"])[1]
    B2 = _basis(Vp2, F2)
    for sparse_target in (truth[body["sparse"]], None):
        p2p = _run(body, Vp2, F2, B2, sparse_target=sparse_target)
        assert p2p.min() >= 0 and p2p.max() < len(V2)
        assert _mean_error(Vp2, F2, p2p, truth) < 0.04
        assert _sides_kept(body, Vp2, F2, p2p, truth)


def test_two_calls_give_identical_maps(body):
    runs = [dense_map(body["V"], body["F"], body["Vp"], body["F"], k=K, k_init=K_INIT, refine_options=FAST)
            for _ in range(2)]
    assert np.array_equal(runs[0], runs[1])


def test_bad_input_is_named(body):
    with pytest.raises(ValueError, match="both meshes"):
        dense_map(body["V"], body["F"], body["Vp"], body["F"], landmarks_template=body["sparse"],
                  basis_template=body["S"], basis_target=body["T"])
    with pytest.raises(ValueError, match="refine"):
        _run(body, body["Vp"], body["F"], body["T"], sparse_target=body["sparse"], refine="smooth")
    with pytest.raises(ValueError, match="target: F must be"):
        dense_map(body["V"], body["F"], body["Vp"], body["F"][:, :2], k=K)


def test_mesh_basis_round_trips_through_a_dict_of_arrays(body):
    from corr_core.correspondence.dense import MeshBasis

    S = body["S"]
    S.sample_distances(5)
    arrays = S.to_arrays()
    assert all(isinstance(v, np.ndarray) for v in arrays.values())
    back = MeshBasis.from_arrays(arrays)
    for key in ("V", "F", "evals", "evecs", "mass", "samples", "vids"):
        assert np.array_equal(getattr(back, key), getattr(S, key)), key
    assert back.area == S.area and back.n_full == S.n_full
    assert np.array_equal(back.sample_distances(5), S.sample_distances(5))
    with pytest.raises(ValueError, match="missing \\['evecs'\\]"):
        MeshBasis.from_arrays({k: v for k, v in arrays.items() if k != "evecs"})


def test_loose_pieces_and_unused_vertices_keep_original_ids(body, pose_maps):
    """A target with a far unused vertex at 1e30 first and a loose triangle: same map, ids shifted by one."""
    V_t, F_t = body["Vp"], body["F"]
    loose = V_t[:3] + np.array([5.0, 0.0, 0.0])
    V_dirty = np.vstack([[[1e30, 1e30, 1e30]], V_t, loose])
    F_dirty = np.vstack([F_t + 1, len(V_t) + 1 + np.array([[0, 1, 2]])])
    B_dirty = _basis(V_dirty, F_dirty)
    assert B_dirty.n == len(V_t) and B_dirty.n_full == len(V_dirty)
    sparse = body["sparse"]
    clean = pose_maps["sparse"]
    dirty = _run(body, V_dirty, F_dirty, B_dirty, sparse_target=sparse + 1)
    assert np.array_equal(dirty, clean + 1)
    with pytest.raises(ValueError, match="largest connected component"):
        _run(body, V_dirty, F_dirty, B_dirty, sparse_target=np.r_[sparse[:-1], len(V_t) + 1])


def test_two_hypotheses_give_a_good_automatic_map_and_rank_the_turn_second(body, pose_maps):
    """The automatic mode refines the two best ranked initial maps (at least; decided by
    ``hypotheses_to_refine``) and keeps the less distorted one: on a pose of the same body it is the right map,
    and the second hypothesis is the 180-degree turn (left and right swapped)."""
    from corr_core.correspondence.dense import automatic_hypotheses, map_automatic

    truth = np.arange(len(body["V"]))
    p2p = pose_maps["auto"]
    assert _mean_error(body["Vp"], body["F"], p2p, truth) < 0.03
    assert _sides_kept(body, body["Vp"], body["F"], p2p, truth)
    maps = automatic_hypotheses(body["S"], body["T"], 2, k_init=K_INIT, k_end=K)
    (Cs, p2ps) = zip(*maps)
    assert len(Cs) == len(p2ps) == 2 and Cs[0].shape == (K, K)
    first = map_automatic(body["S"], body["T"], k_init=K_INIT, k_end=K)        # map_automatic's is the first
    assert np.array_equal(first[0], Cs[0]) and np.array_equal(first[1], p2ps[0])
    samples = body["S"].samples[:len(p2ps[1])]
    far = np.linalg.norm(body["T"].V[p2ps[1]] - body["T"].V[samples], axis=1) > 0.1   # T.V: unit area
    assert far.mean() > 0.5                                           # the other hypothesis is a different map
    assert 2 <= len(automatic_hypotheses(body["S"], body["T"], k_init=K_INIT, k_end=K)) <= 3   # decided there
    with pytest.raises(ValueError, match="n must be >= 1"):
        automatic_hypotheses(body["S"], body["T"], 0)


def test_the_chirality_weight_reaches_the_probes(body):
    """``automatic_hypotheses(chirality_weight=0)`` (bench/dense_constants.py sweeps it) fits the probes without
    chirality columns, so no candidate has a chirality agreement; at the default every candidate has one."""
    from corr_core.correspondence.dense import automatic_hypotheses

    def agreements(**kw):
        _, info = automatic_hypotheses(body["S"], body["T"], 1, k_init=K_INIT, k_end=K, return_info=True, **kw)
        return np.array([c.chirality for c in info["candidates"]])

    assert np.all(agreements(chirality_weight=0.0) == 0.0)
    assert np.all(np.abs(agreements()) > 0.05)


def test_hypotheses_to_refine_takes_the_best_two_and_any_close_pool_candidate():
    from corr_core.correspondence.dense.init import HYPOTHESIS_WKS_RATIO, hypotheses_to_refine

    def ranked(*pairs):
        return hypotheses_to_refine([c for c, _ in pairs], [w for _, w in pairs])

    assert ranked((0.8, 0.05), (0.3, 0.09)) == 2                                     # the runner-up, always
    close = 0.05 * (HYPOTHESIS_WKS_RATIO - 0.01)
    assert ranked((0.8, 0.05), (0.8, 0.051), (0.79, close), (0.8, close)) == 3       # at most 3
    assert ranked((0.8, 0.05), (0.8, 0.051), (0.3, close)) == 2                      # a twist: not in the pool
    assert ranked((0.8, 0.05), (0.8, 0.051), (0.8, 0.08)) == 2                       # far in WKS
    assert ranked((0.8, 0.05)) == 1 and ranked() == 0


def test_given_points_go_where_they_are_given(body, pose_maps):
    """The map from given points sends each template point to its given target point, also when those are a
    vertex off the truth (a user's click): the refinement holds them instead of pulling them back."""
    assert np.array_equal(pose_maps["sparse"][body["sparse"]], body["sparse"])
    ring = cKDTree(body["Vp"]).query(body["Vp"][body["sparse"]], k=2)[1][:, 1]      # nearest other vertex
    p2p = _run(body, body["Vp"], body["F"], body["T"], sparse_target=ring)
    assert np.array_equal(p2p[body["sparse"]], ring)
