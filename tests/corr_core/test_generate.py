"""Tests of the generated default data (corr_core.generate): chairs with known azimuths, posed humanoid."""
from __future__ import annotations

import csv
import filecmp

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from corr_core.generate import chairs as C
from corr_core.generate import humanoid as H
from corr_core.geometry.mesh_io import load_mesh
from corr_core.geometry.primitives import rotate_about_y

COURSE_LANDMARK_NAMES = ["Left Toe", "Right Toe", "Left Knee", "Right Knee", "Left Hip", "Right Hip", "Left Hand",
                         "Right Hand", "Left Elbow", "Right Elbow", "Left Sholder", "Right Sholder", "Left Side",
                         "Right Side", "Left Chest", "Right Chest", "Left Back", "Right Back", "Vertex", "Belly"]


def _edges(F: np.ndarray) -> np.ndarray:
    return np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])


def _unique_edges(F: np.ndarray) -> np.ndarray:
    return np.unique(np.sort(_edges(F), axis=1), axis=0)


# ------------------------------------------------------------------------------------------------------ chairs


@pytest.fixture(scope="module")
def chair_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("chairs")
    info = C.write_chair_collection(out, n=24, seed=0, views=16)
    return out, info


def test_chair_collection_deterministic(chair_dir, tmp_path):
    out, _ = chair_dir
    C.write_chair_collection(tmp_path / "again", n=24, seed=0)
    C.write_chair_collection(tmp_path / "other", n=24, seed=1)
    names = [f"{i:03d}.obj" for i in range(1, 25)] + ["ground_truth.csv"]
    match, mismatch, errors = filecmp.cmpfiles(out, tmp_path / "again", names, shallow=False)
    assert len(match) == 25 and not mismatch and not errors
    _, mismatch, _ = filecmp.cmpfiles(out, tmp_path / "other", names, shallow=False)
    assert len(mismatch) >= 20


def test_ground_truth_csv(chair_dir):
    out, info = chair_dir
    with open(out / "ground_truth.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0].keys()) == ["shape", "azimuth_steps", "azimuth_deg"]
    assert [r["shape"] for r in rows] == [f"{i:03d}" for i in range(1, 25)]
    steps = np.array([int(r["azimuth_steps"]) for r in rows])
    deg = np.array([float(r["azimuth_deg"]) for r in rows])
    assert steps.min() >= 0 and steps.max() < 16
    np.testing.assert_allclose(deg, steps * 22.5)
    np.testing.assert_array_equal(steps, info["azimuth_steps"])
    assert len(np.unique(steps)) >= 8  # uniformly random, not constant


def test_written_chairs_unrotate_to_canonical(chair_dir):
    out, info = chair_dir
    for i in range(1, 25):
        V, F = load_mesh(out / f"{i:03d}.obj")
        V0, F0 = C.make_chair(C.chair_rng(0, i), kind=C.chair_kind(i))
        np.testing.assert_array_equal(F, F0)
        a = info["azimuth_steps"][i - 1] * 2 * np.pi / 16
        np.testing.assert_allclose(rotate_about_y(V, -a), V0, atol=1e-7)
        if info["azimuth_steps"][i - 1] not in (0, 8):  # a real rotation changes the file's coordinates
            assert np.abs(V - V0).max() > 0.05


def test_chairs_valid_varied_and_fronted():
    extents, tris = [], []
    for i in range(1, 25):
        V, F = C.canonical_chair(0, i)
        assert np.isfinite(V).all() and len(F) > 0 and F.min() >= 0 and F.max() < len(V)
        ext = V.max(0) - V.min(0)
        assert abs(ext.max() - 1.0) < 1e-9 and np.allclose(V.min(0) + V.max(0), 0, atol=1e-9)
        assert ext[1] > 0.6  # chairs are tall
        # clear front: the top of the chair (backrest) lies at the back (-z)
        top = V[:, 1] > V[:, 1].max() - 0.1
        assert V[top, 2].mean() < -0.15
        extents.append(ext)
        tris.append(len(F))
    extents = np.array(extents)
    d = np.linalg.norm(extents[:, None] - extents[None], axis=2)
    assert d[np.triu_indices(24, 1)].min() > 1e-3  # all bounding boxes differ
    assert extents[:, [0, 2]].std(0).min() > 0.02  # widths and depths vary (height is the largest side)
    assert 500 <= min(tris) and max(tris) <= 3000


def _signed_volume(V: np.ndarray, F: np.ndarray) -> float:
    """Volume enclosed by a closed triangle mesh, positive when its faces point outward."""
    return float(np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6.0)


def test_cylinder_side_and_cap_normals_point_outward():
    a, b = np.array([0.1, -0.2, 0.3]), np.array([0.4, 0.5, -0.1])
    V, F = C.cylinder(a, b, 0.05, segments=10, rings=3, radius_b=0.07)
    w = (b - a) / np.linalg.norm(b - a)
    normal = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    centre = V[F].mean(axis=1)
    along = (centre - a) @ w
    radial = centre - a - along[:, None] * w
    side = (along > 1e-9) & (along < np.linalg.norm(b - a) - 1e-9)
    cap_a, cap_b = np.abs(along) < 1e-9, np.abs(along - np.linalg.norm(b - a)) < 1e-9
    assert side.sum() == 2 * 3 * 10 and cap_a.sum() == 10 and cap_b.sum() == 10
    assert np.all(np.einsum("ij,ij->i", normal[side], radial[side]) > 0)
    assert np.all(normal[cap_a] @ w < 0) and np.all(normal[cap_b] @ w > 0)


def test_every_generated_chair_part_is_consistently_outward_oriented(monkeypatch):
    """Each part (box, cylinder) of the generated chairs is closed once welded, needs no face flipped for a
    consistent orientation and encloses a positive volume (faces point outward)."""
    from corr_core.geometry.repair import orient_faces

    parts = []
    for maker in ("box", "cylinder"):
        make = getattr(C, maker)
        monkeypatch.setattr(C, maker, lambda *a, _make=make, **kw: parts.append(_make(*a, **kw)) or parts[-1])
    for i in (1, 2, 3, 4, 5, 6, 7, 8, 18):
        parts.clear()
        C.canonical_chair(0, i)
        assert parts, i
        for k, (V, F) in enumerate(parts):
            Vw, Fw = C.weld(V, F)
            assert orient_faces(Fw)[1] == 0, (i, k)
            assert _signed_volume(Vw, Fw) > 0, (i, k)


def test_pedestal_chair_has_star_base():
    V, _ = C.make_chair(np.random.default_rng(3), kind="pedestal")
    low = V[V[:, 1] < V[:, 1].min() + 0.03]
    ang = np.arctan2(low[:, 2], low[:, 0])
    r = np.hypot(low[:, 0], low[:, 2])
    feet = np.unique(np.round(ang[r > 0.2] / (2 * np.pi / 5)))  # 5 casters at 72-degree spacing
    assert len(feet) == 5
    assert C.chair_kind(6) == "pedestal" and C.chair_kind(18) == "pedestal" and C.chair_kind(5) == "legs"


# ---------------------------------------------------------------------------------------------------- humanoid


@pytest.fixture(scope="module")
def human(tmp_path_factory):
    out = tmp_path_factory.mktemp("human")
    info = H.write_humanoid_dataset(out, n_poses=6, seed=0)
    V, F = load_mesh(out / "meshes" / "template" / "mesh000.obj")
    posed = [load_mesh(p) for p in info["tests"]]
    return out, info, V, F, posed


def test_humanoid_layout_and_determinism(human, tmp_path):
    out, info, V, F, posed = human
    assert [p.rsplit("/", 1)[-1] for p in info["tests"]] == [f"mesh{i:03d}.obj" for i in range(1, 7)]
    again = H.write_humanoid_dataset(tmp_path, n_poses=6, seed=0)
    for a, b in zip([info["template"]] + info["tests"], [again["template"]] + again["tests"]):
        assert filecmp.cmp(a, b, shallow=False)
    for name in ("landmark_vids.txt", "sparse_landmark_vids.txt"):
        assert filecmp.cmp(out / name, tmp_path / name, shallow=False)
    other = H.make_humanoid_dataset(n_poses=2, seed=1)[2]
    assert np.abs(other[0] - posed[0][0]).max() > 0.05


def test_humanoid_same_connectivity(human):
    _, _, V, F, posed = human
    for Vp, Fp in posed:
        assert Vp.shape == V.shape
        np.testing.assert_array_equal(Fp, F)
        assert np.abs(Vp - V).max() > 0.05  # actually posed


def test_humanoid_closed_manifold_sphere(human):
    _, _, V, F, _ = human
    assert 3000 <= len(V) <= 6000
    E = _unique_edges(F)
    _, counts = np.unique(np.sort(_edges(F), axis=1), axis=0, return_counts=True)
    assert np.all(counts == 2)  # closed, edge-manifold
    directed = _edges(F)
    assert len(np.unique(directed, axis=0)) == len(directed)  # consistently oriented
    assert len(V) - len(E) + len(F) == 2  # sphere topology (with one component)
    import scipy.sparse as sp
    A = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(len(V), len(V)))
    assert connected_components(A, directed=False)[0] == 1
    assert len(np.unique(F.ravel())) == len(V)  # no unused vertices
    # vertex-manifold: around each vertex the faces form a single fan (link is one cycle)
    from corr_core.open3d_loader import load_open3d
    o3d = load_open3d()
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32)))
    assert m.is_vertex_manifold() and m.is_edge_manifold()
    # no degenerate faces; outward orientation (positive volume)
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    assert area.min() > 1e-3 * np.median(area)
    assert np.einsum("ij,ij->i", V[F[:, 0]], cross).sum() > 0


def test_humanoid_near_isometric(human):
    _, _, V, F, posed = human
    E = _unique_edges(F)
    L = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    stats = []
    for Vp, _ in posed:
        r = np.abs(np.linalg.norm(Vp[E[:, 0]] - Vp[E[:, 1]], axis=1) / L - 1)
        stats.append(np.percentile(r, [50, 95]))
    stats = np.array(stats)
    print("edge length relative change per pose (median, 95th pct):", stats.round(3).tolist())
    # SCAPE itself (course data) has median ~0.10 and 95th ~0.40
    assert stats[:, 0].max() < 0.05 and stats[:, 1].max() < 0.30


def test_humanoid_rest_symmetric(human):
    _, _, V, F, _ = human
    mirrored = V * [-1.0, 1.0, 1.0]
    d_ab = cKDTree(V).query(mirrored)[0].max()
    d_ba = cKDTree(mirrored).query(V)[0].max()
    assert max(d_ab, d_ba) < 1e-6  # Hausdorff (vertex sets) between mesh and its mirror
    # the connectivity is mirrored too: the mirror of every face (reversed) is a face
    pair = cKDTree(V).query(mirrored)[1]
    faces = {tuple(sorted(f)) for f in F.tolist()}
    assert all(tuple(sorted(f)) in faces for f in pair[F].tolist())


def test_humanoid_landmarks(human):
    out, info, V, F, _ = human
    lines = (out / "landmark_vids.txt").read_text().strip().splitlines()
    vids = [int(line.split(",")[0]) for line in lines]
    names = [line.split(",", 1)[1] for line in lines]
    assert names == COURSE_LANDMARK_NAMES
    assert len(set(vids)) == 20 and min(vids) >= 0 and max(vids) < len(V)
    lm = dict(zip(names, vids))
    for name in names:
        if name.startswith("Left"):
            left, right = V[lm[name]], V[lm["Right" + name[4:]]]
            assert left[0] > 0.02
            np.testing.assert_allclose(left, right * [-1, 1, 1], atol=1e-6)
    # anatomical sanity: head top is the highest, hands the most lateral, toes low and in front
    assert V[lm["Vertex"], 1] > V[:, 1].max() - 0.01
    assert V[lm["Left Hand"], 0] > V[:, 0].max() - 0.03
    assert V[lm["Left Toe"], 1] < 0.1 and V[lm["Left Toe"], 2] > 0.1
    assert V[lm["Left Knee"], 1] > 0.4 and V[lm["Left Knee"], 1] < 0.6 and V[lm["Left Knee"], 2] > 0
    assert V[lm["Left Chest"], 2] > 0 > V[lm["Left Back"], 2]
    sparse = (out / "sparse_landmark_vids.txt").read_text().strip().splitlines()
    assert [s.split(",", 1)[1] for s in sparse] == ["Left Toe", "Right Toe", "Left Hand", "Right Hand", "Vertex"]
    assert all(lm[s.split(",", 1)[1]] == int(s.split(",")[0]) for s in sparse)


def test_pose_kinematics():
    V, F = H.make_humanoid_rest()
    W, names = H.skinning_weights(V, F)
    zero = {k: 0.0 for k in H.random_pose(np.random.default_rng(0))}
    np.testing.assert_allclose(H.pose_mesh(V, W, zero), V, atol=1e-12)
    bent = dict(zero, L_elbow=90.0)
    Vb = H.pose_mesh(V, W, bent)
    # under an elbow-only pose the forearm and the hand move with the same rigid transform
    hand = np.abs(W[:, names.index("L_forearm")] + W[:, names.index("L_hand")] - 1.0) < 1e-12
    rest = (W[:, names.index("L_forearm")] == 0) & (W[:, names.index("L_hand")] == 0)
    assert hand.sum() > 20 and rest.sum() > 0.8 * len(V)
    np.testing.assert_allclose(Vb[rest], V[rest], atol=1e-12)  # vertices not bound to the forearm/hand stay put
    D0 = np.linalg.norm(V[hand][:, None] - V[hand][None], axis=2)
    Db = np.linalg.norm(Vb[hand][:, None] - Vb[hand][None], axis=2)
    np.testing.assert_allclose(Db, D0, atol=1e-9)  # rigid motion of the hand
    J = H.skeleton()
    # the fingertip swings forward (+z) by about the forearm+hand length
    tip = np.argmax(V[:, 0])
    assert Vb[tip, 2] - V[tip, 2] > 0.3
    assert np.linalg.norm(Vb[tip] - J["L_elbow"]) == pytest.approx(np.linalg.norm(V[tip] - J["L_elbow"]), abs=1e-9)
