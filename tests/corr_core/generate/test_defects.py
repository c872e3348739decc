"""Made defects keep the mesh's own vertex ids and make exactly the defect they name."""
import numpy as np

from corr_core.generate.defects import cut_along_a_seam, with_fins
from corr_core.geometry.primitives import unique_edges, vertex_components
from tests.helpers import sphere


def test_a_seam_cut_repeats_the_shared_vertices_and_splits_the_surface():
    V, F = sphere(300)
    side = V[F].mean(axis=1)[:, 2] > 0
    V2, F2, shared, copies = cut_along_a_seam(V, F, side)
    np.testing.assert_array_equal(V2[:len(V)], V)
    np.testing.assert_array_equal(V2[copies], V[shared])
    np.testing.assert_array_equal(F2[~side], F[~side])
    assert vertex_components(len(V2), F2)[0] == 2 and len(shared) > 10


def test_fins_stand_on_edges_with_new_apexes():
    V, F = sphere(300)
    V2, F2 = with_fins(V, F, 7, seed=1)
    np.testing.assert_array_equal(V2[:len(V)], V)
    np.testing.assert_array_equal(F2[:len(F)], F)
    assert (F2[len(F):, 2] == len(V) + np.arange(7)).all()
    _, counts = unique_edges(F2)
    assert (counts == 3).sum() == 7 and (np.linalg.norm(V2[len(V):], axis=1) > 1.01).all()   # outside the sphere
