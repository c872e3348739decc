"""Mesh primitives: areas, normals, centroid, edges, components, triangle sets, rotations about y."""
import numpy as np
import pytest

from corr_core.geometry.primitives import (edge_keys, face_areas, face_normals, largest_component, manifold_patches,
                                           mesh_edges, without_fins,
                                           rotate_about_y, rotation_about_y, same_triangles, surface_area,
                                           surface_centroid, unique_edges, vertex_adjacency, vertex_components,
                                           vertex_normals)
from corr_core.generate.defects import with_fins
from tests.helpers import sphere

TETRA_V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])  # outward


def test_face_areas_normals_and_surface_area():
    V = np.array([[0.0, 0, 0], [2, 0, 0], [0, 3, 0], [1, 1, 0]])
    F = np.array([[0, 1, 2], [2, 1, 0], [0, 1, 1]])  # ccw, cw, degenerate
    np.testing.assert_allclose(face_areas(V, F), [3.0, 3.0, 0.0])
    np.testing.assert_allclose(face_normals(V, F), [[0, 0, 1], [0, 0, -1], [0, 0, 0]])
    assert surface_area(V, F) == pytest.approx(6.0)
    Vs, Fs = sphere(2000)
    assert surface_area(Vs, Fs) == pytest.approx(4 * np.pi, rel=0.01)


def test_vertex_normals_point_outward_on_a_sphere():
    V, F = sphere(800)
    N = vertex_normals(V, F)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0)
    assert np.min(np.sum(N * V, axis=1)) > 0.98
    assert np.max(np.sum(vertex_normals(V, F[:, ::-1]) * V, axis=1)) < -0.98  # winding decides the side


def test_surface_centroid_ignores_tessellation_density():
    # unit square in z=0: one half split into many thin triangles; the vertex mean moves, the centroid does not
    xs = np.linspace(0, 0.5, 11)
    V = np.array([[x, y, 0.0] for x in xs for y in (0.0, 1.0)] + [[1.0, 0, 0], [1.0, 1, 0]])
    F = [[2 * i, 2 * i + 2, 2 * i + 1] for i in range(10)] + [[2 * i + 1, 2 * i + 2, 2 * i + 3] for i in range(10)]
    F += [[20, 22, 21], [21, 22, 23]]
    c = surface_centroid(V, np.array(F))
    np.testing.assert_allclose(c, [0.5, 0.5, 0.0], atol=1e-12)
    assert abs(V.mean(axis=0)[0] - 0.5) > 0.1
    np.testing.assert_allclose(surface_centroid(V, np.array([[0, 0, 0]])), V.mean(axis=0))  # zero area: mean


def test_unique_edges_counts_boundary_and_interior():
    E, count = unique_edges(TETRA_F)
    assert len(E) == 6 and np.all(count == 2) and np.all(E[:, 0] < E[:, 1])
    E1, count1 = unique_edges(TETRA_F[:3])  # open: the three edges of the missing face are boundary
    assert sorted(map(tuple, E1[count1 == 1])) == [(1, 2), (1, 3), (2, 3)]


def test_unique_edges_match_a_row_wise_unique_on_a_sphere():
    _, F = sphere(300)
    E, count = unique_edges(F)
    half = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    ref, ref_count = np.unique(np.sort(half, axis=1), axis=0, return_counts=True)
    np.testing.assert_array_equal(E, ref)
    np.testing.assert_array_equal(count, ref_count)
    assert np.all(count == 2)  # closed surface
    k = edge_keys(np.array([[3, 5], [5, 3], [0, 9]]))
    assert k[0] == k[1] != k[2]


def test_mesh_edges_number_by_first_appearance():
    edges, face_edges = mesh_edges(TETRA_F)
    np.testing.assert_array_equal(edges[:3], [[0, 2], [2, 1], [1, 0]])
    assert len(edges) == 6
    for f, tri in enumerate(TETRA_F):
        for k in range(3):
            assert sorted(edges[face_edges[f, k]]) == sorted([tri[k], tri[(k + 1) % 3]])


def two_components():
    """A big single triangle (area 50, 3 vertices) and a small fan (area 0.5, 7 vertices)."""
    big_V = np.array([[0.0, 0, 0], [10, 0, 0], [0, 10, 0]])
    t = np.linspace(0, np.pi / 2, 6)
    fan_V = np.c_[np.cos(t), np.sin(t), np.zeros(6)] * 0.8 + [20, 0, 0]
    V = np.concatenate([big_V, [[20.0, 0, 0]], fan_V])
    F = np.concatenate([[[0, 1, 2]], [[3, 4 + i, 5 + i] for i in range(5)]])
    return V, F


def test_components_and_largest_by_area_or_vertices():
    V, F = two_components()
    n, labels = vertex_components(len(V), F)
    assert n == 2 and labels[0] == labels[1] == labels[2] != labels[3]
    V2, F2, kept = largest_component(V, F)
    np.testing.assert_array_equal(kept, [0, 1, 2])
    np.testing.assert_array_equal(V2[F2], V[F[:1]])
    _, F3, kept3 = largest_component(V, F, by="vertices")
    np.testing.assert_array_equal(kept3, np.arange(3, 10))
    assert F3.min() == 0 and F3.max() == 6
    with pytest.raises(ValueError, match="by must be"):
        largest_component(V, F, by="faces")


def test_fins_are_patches_of_their_own_and_without_fins_keeps_the_surface():
    V, F = sphere(200)
    n, labels = manifold_patches(F)
    assert n == 1 and not labels.any()
    assert without_fins(V, F) is F                                  # no non-manifold edge: the same array
    V2, F2 = with_fins(V, F, 3)
    n, labels = manifold_patches(F2)
    assert n == 4 and len(np.unique(labels[len(F):])) == 3 and (labels[:len(F)] == labels[0]).all()
    assert labels[0] not in labels[len(F):]
    np.testing.assert_array_equal(without_fins(V2, F2), F)
    V3 = np.vstack([V, V + [3.0, 0, 0]])                              # two spheres, no fin: both kept
    F3 = np.vstack([F, F + len(V)])
    assert manifold_patches(F3)[0] == 2 and without_fins(V3, F3) is F3


def test_vertex_adjacency_is_symmetric_binary():
    A = vertex_adjacency(TETRA_F, 5).toarray()
    np.testing.assert_array_equal(A, A.T)
    assert set(np.unique(A)) == {0.0, 1.0}
    assert A[:4, :4].sum() == 12 and A[4].sum() == 0  # tetrahedron: every pair joined; vertex 4 unused


def test_same_triangles_ignores_face_and_corner_order():
    shuffled = TETRA_F[[2, 0, 3, 1]][:, [1, 2, 0]]
    assert same_triangles(TETRA_F, shuffled)
    other = TETRA_F.copy()
    other[0] = [0, 1, 2]  # same vertex set as face 0: still the same triangles
    assert same_triangles(TETRA_F, other)
    other[1] = [0, 1, 1]
    assert not same_triangles(TETRA_F, other)
    assert not same_triangles(TETRA_F, TETRA_F[:3])


def test_rotation_about_y_known_values():
    np.testing.assert_allclose(rotate_about_y(np.array([[1.0, 0, 0]]), np.pi / 2), [[0, 0, -1]], atol=1e-12)
    np.testing.assert_allclose(rotate_about_y(np.array([[0, 0, 1.0]]), np.pi / 2), [[1, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(rotate_about_y(np.array([[0.3, 2.0, -1]]), 1.1)[:, 1], [2.0])
    R = rotation_about_y(0.7)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(R), 1.0)
    composed = rotation_about_y(0.3) @ rotation_about_y(0.4)
    np.testing.assert_allclose(composed, rotation_about_y(0.7), atol=1e-12)
    assert rotate_about_y(np.array([[1, 0, 0]]), 0.1).dtype == np.float64  # ints become float64
    assert rotate_about_y(np.ones((2, 3), np.float32), 0.1).dtype == np.float32
    with pytest.raises(ValueError):
        rotate_about_y(np.zeros((4, 2)), 0.1)
