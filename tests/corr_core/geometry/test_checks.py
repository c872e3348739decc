"""Mesh checks on tiny synthetic meshes with known defects."""
import re

import numpy as np
import pytest

from corr_core.geometry.checks import check_correspondence_mesh, check_same_connectivity
from corr_core.geometry.primitives import largest_component
from corr_core.geometry.mesh_io import MeshError

TET_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def test_closed_tetrahedron_is_clean():
    assert check_correspondence_mesh(TET_V, TET_F, "tet") == []


def test_open_surface_and_unused_vertex_warn():
    V = np.vstack([TET_V, [[5, 5, 5]]])
    warns = check_correspondence_mesh(V, TET_F[:3], "open")
    assert any("3 boundary edge" in w for w in warns)
    assert any("used by no face" in w and "4" in w for w in warns)


def test_non_manifold_edge_warns():
    V = np.vstack([TET_V, [[0, -1, 0.5]]])
    F = np.vstack([TET_F, [[0, 1, 4]]])  # edge (0,1) now has three faces
    warns = check_correspondence_mesh(V, F, "fin")  # the intrinsic methods still run: a warning, kept
    assert any(re.search(r"fin: 1 non-manifold edge.*\(0, 1\)", w) for w in warns)


def test_degenerate_faces_raise():
    V = np.vstack([TET_V, [[0.5, 0.5, 0]]])  # vertex 4 on the edge 1-2
    with pytest.raises(MeshError, match="degenerate"):
        check_correspondence_mesh(V, np.vstack([TET_F, [[1, 2, 4]]]), "flat")
    with pytest.raises(MeshError, match="degenerate"):
        check_correspondence_mesh(TET_V, np.vstack([TET_F, [[0, 0, 1]]]), "repeated")


def test_components_raise_or_warn_and_repair():
    V = np.vstack([TET_V, TET_V * 0.1 + 5.0])
    F = np.vstack([TET_F, TET_F + 4])
    with pytest.raises(MeshError, match="2 connected components"):
        check_correspondence_mesh(V, F, "two")
    assert any("2 connected components" in w for w in check_correspondence_mesh(V, F, "two", allow_components=True))
    V2, F2, kept = largest_component(V, F)
    np.testing.assert_array_equal(kept, [0, 1, 2, 3])  # the bigger tetrahedron
    np.testing.assert_array_equal(V2, TET_V)
    assert check_correspondence_mesh(V2, F2, "repaired") == []


def test_same_connectivity():
    check_same_connectivity(TET_F, TET_F.copy(), "a", "b", 4, 4)
    with pytest.raises(MeshError, match="b has 5"):
        check_same_connectivity(TET_F, TET_F, "a", "b", 4, 5)
    with pytest.raises(MeshError, match="b has 3"):
        check_same_connectivity(TET_F, TET_F[:3], "a", "b")
    swapped = TET_F.copy()
    swapped[2] = swapped[2, [1, 0, 2]]
    with pytest.raises(MeshError, match="face 2"):
        check_same_connectivity(TET_F, swapped, "a", "b")


def test_unreferenced_vertices_error_when_not_allowed():
    V = np.vstack([TET_V, [[1e30, 0, 0]]])
    assert any("used by no face" in w for w in check_correspondence_mesh(V, TET_F, "stray"))
    with pytest.raises(MeshError, match="stray: 1 vertex used by no face.*remove"):
        check_correspondence_mesh(V, TET_F, "stray", allow_unreferenced=False)


def test_far_unreferenced_vertex_does_not_make_faces_degenerate():
    V = np.vstack([TET_V, [[1e30, 0, 0]]])  # would set a 1e30 bounding box: every face "zero-area"
    check_correspondence_mesh(V, TET_F, "far")
