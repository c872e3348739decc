"""Orientation (chirality) test: invariance, mirror symmetry resolved, and SCAPE accuracy (course)."""
import numpy as np
import pytest

from corr_core.correspondence.landmark_mrf import match_landmarks_mrf
from corr_core.correspondence.orientation import (chirality_agreement, landmark_chirality, match_landmarks_oriented,
                                                  reliable_triples)
from tests.helpers import COURSE_DATA, normalized_distances, sphere


def mirror_symmetric_blob():
    """Surface symmetric under x -> -x (vertices are not), with 4 mirror pairs and 2 plane landmarks."""
    V, F = sphere(1500)
    r = 1 + 0.4 * np.exp(-((np.abs(V[:, 0]) - 0.6) ** 2 + (V[:, 2] - 0.5) ** 2) / 0.1) + 0.3 * np.exp(-(V[:, 1] + 0.7) ** 2 / 0.1)
    V = V * r[:, None] * [1.0, 0.9, 1.6]
    nearest = lambda p: int(np.argmin(np.linalg.norm(V - p, axis=1)))
    left = [nearest(V[i]) for i in np.flatnonzero(V[:, 0] > 0.3)[[0, 150, 300, 450]]]
    right = [nearest(V[i] * [-1, 1, 1]) for i in left]
    plane = [nearest(np.array([0.0, -1.2, 0.0])), nearest(np.array([0.0, 0.5, 1.5]))]
    vids = np.array(left + right + plane)
    mirror = np.array([4, 5, 6, 7, 0, 1, 2, 3, 8, 9])  # landmark index of each landmark's mirror image
    return V, F, vids, mirror


def test_chirality_flips_under_mirror_and_survives_rigid_motion():
    V, F, vids, _ = mirror_symmetric_blob()
    C = landmark_chirality(V, F, vids)
    c, s = np.cos(0.8), np.sin(0.8)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    np.testing.assert_allclose(landmark_chirality(V @ R.T + 3.0, F, vids), C, atol=1e-10)
    mirrored = landmark_chirality(V * [-1, 1, 1], F[:, ::-1], vids)  # winding reversed: normals stay outward
    np.testing.assert_allclose(mirrored, -C, atol=1e-10)
    np.testing.assert_allclose(C, -C.transpose(0, 2, 1), atol=1e-12)


def test_oriented_matching_resolves_mirror_symmetry():
    V, F, vids, mirror = mirror_symmetric_blob()
    dT = normalized_distances(V[vids])
    chiT = landmark_chirality(V, F, vids)
    # test shape: the mirror image (an isometry) with the same vertex ids -> distances are identical, so the
    # geodesic MRF alone prefers i -> i, which is the MIRRORED answer; the true match is i -> mirror[i]
    V2, F2 = (V * [-1, 1, 1]) @ np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1.0]]).T, F[:, ::-1]
    dS = normalized_distances(V2[vids])
    chiS = landmark_chirality(V2, F2, vids)
    mask = reliable_triples(dT, chiT)
    assert mask.sum() >= 30
    pure = match_landmarks_mrf(dT, dS, sigma=0.01)
    assert chirality_agreement(chiT, chiS, mirror, mask) > 0.9 > 0.1 > chirality_agreement(chiT, chiS, np.arange(10), mask)
    # the rigidly moved (not mirrored) copy has exactly the same distances, so the pure MRF cannot tell the two
    # cases apart; orientation must give the identity there and the mirror pairing above
    V3 = V @ np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1.0]]).T
    chi3 = landmark_chirality(V3, F, vids)
    np.testing.assert_allclose(normalized_distances(V3[vids]), dS, atol=1e-12)
    assert pure.tolist() in (np.arange(10).tolist(), mirror.tolist())
    for cw in [0.0, 1.0]:
        np.testing.assert_array_equal(match_landmarks_oriented(dT, dS, chiT, chiS, sigma=0.01, chirality_weight=cw), mirror)
        np.testing.assert_array_equal(match_landmarks_oriented(dT, dS, chiT, chi3, sigma=0.01, chirality_weight=cw), np.arange(10))


@pytest.mark.course
@pytest.mark.skipif(not (COURSE_DATA / "scape").is_dir(), reason=f"course data not found at {COURSE_DATA / 'scape'}")
def test_scape_three_meshes_accuracy():
    """Measured on mesh002/004/005: WKS (k=30 eigenpairs, to keep the test short) + Hungarian 0.767
    (0.6/0.7/1.0), geodesic MRF sigma=0.05 0.767 (1.0/0.3/1.0), oriented MRF 0.933 (1.0/0.8/1.0);
    thresholds are those minus a margin."""
    from corr_core.correspondence.descriptors import descriptor_distance, wks
    from corr_core.geometry.geodesic import landmark_geodesics
    from corr_core.correspondence.landmarks import read_landmarks
    from corr_core.geometry.laplacian import eigenpairs
    from corr_core.correspondence.matching import hungarian_match
    from corr_core.geometry.mesh_io import load_mesh

    scape = COURSE_DATA / "scape"
    paths = [scape / "meshes/template/mesh000.obj"] + [scape / f"meshes/test/mesh{i}.obj" for i in ("002", "004", "005")]
    meshes = [load_mesh(p) for p in paths]
    ids, _ = read_landmarks(scape / "landmark_vids.txt", len(meshes[0][0]))
    feats = []
    for V, F in meshes:
        ev, ph = eigenpairs(V, F, k=30)
        feats.append((wks(ev, ph[ids]), landmark_geodesics(V, F, ids), landmark_chirality(V, F, ids)))
    truth = np.arange(len(ids))
    acc = {"wks": [], "mrf": [], "oriented": []}
    for wks_s, geo_s, chi_s in feats[1:]:
        acc["wks"].append(np.mean(hungarian_match(descriptor_distance(feats[0][0], wks_s)) == truth))
        acc["mrf"].append(np.mean(match_landmarks_mrf(feats[0][1], geo_s, sigma=0.05) == truth))
        oriented = match_landmarks_oriented(feats[0][1], geo_s, feats[0][2], chi_s, sigma=0.05)
        acc["oriented"].append(np.mean(oriented == truth))
    assert np.mean(acc["wks"]) >= 0.65, acc
    assert np.mean(acc["mrf"]) >= 0.6, acc
    assert np.mean(acc["oriented"]) >= 0.8, acc
