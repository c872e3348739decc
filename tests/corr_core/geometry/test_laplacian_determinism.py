"""Same mesh, same eigenpairs, bit for bit: eigsh starts from a fixed vector (from ARPACK's random start,
eigenvectors differ by ~1e-15 between calls, which breaks ties downstream)."""
import numpy as np

from corr_core.geometry import laplacian
from tests.helpers import sphere


def test_eigenpairs_are_bit_identical_across_calls():
    V, F = sphere(600)
    first = laplacian.eigenpairs(V, F, k=20)
    for _ in range(2):
        again = laplacian.eigenpairs(V, F, k=20)
        np.testing.assert_array_equal(again[0], first[0])
        np.testing.assert_array_equal(again[1], first[1])


def test_start_vector_is_fixed_and_not_smooth():
    v = laplacian.start_vector(50)
    np.testing.assert_array_equal(v, laplacian.start_vector(50))
    assert abs(np.corrcoef(v, np.ones(50) + np.arange(50) * 1e-9)[0, 1]) < 0.5  # far from the constant mode
