"""The functional-map fit with the orientation term solves the energy of ``fmaps`` (not only its pieces)."""
from __future__ import annotations

import numpy as np

from corr_core.correspondence.dense import fmaps


def _planted(k: int = 8, q: int = 3, n_orient: int = 2, seed: int = 0):
    """A planted map C0 (a diagonal of signs: the sign ambiguity of eigenvectors) that zeroes all three terms:
    A_S = C0 A_T, same distinct eigenvalues (off-diagonal entries cost), Om_S = C0 Om_T C0^T (commutes)."""
    rng = np.random.default_rng(seed)
    C0 = np.diag(rng.choice([-1.0, 1.0], size=k))
    A_T = rng.normal(size=(k, q))
    evals = np.sort(rng.uniform(1.0, 50.0, size=k))
    G = rng.normal(size=(n_orient, k, k))
    Om_T = G - np.swapaxes(G, 1, 2)                      # antisymmetric, like the real operators
    Om_S = np.einsum("ij,qjk,lk->qil", C0, Om_T, C0)
    return C0, C0 @ A_T, A_T, evals, Om_S, Om_T


def test_fit_with_the_orientation_term_recovers_a_planted_map_that_zeroes_the_energy():
    """Fewer descriptors (3) than basis functions (8): the descriptor term alone does not pin the map down;
    with the Laplacian and orientation terms the unique zero of the energy is the planted map. A sign error in
    the orientation term's cross products (||C Om_T + Om_S C||) moves the solution away from it."""
    C0, A_S, A_T, evals, Om_S, Om_T = _planted()
    C = fmaps.fit_functional_map(A_S, A_T, evals, evals, Om_S, Om_T, w_descr=1.0, w_lap=0.1, w_orient=1.0)
    np.testing.assert_allclose(C, C0, atol=1e-6)
    commutator = np.einsum("ij,qjk->qik", C, Om_T) - np.einsum("qij,jk->qik", Om_S, C)
    assert np.abs(commutator).max() < 1e-6


def test_orientation_term_tells_the_planted_map_from_its_mirror():
    """The operators of a mirror image change sign (Om_S -> -Om_S): the fit then cannot zero the orientation
    term with C0, and its map differs from the one fitted to the planted operators."""
    C0, A_S, A_T, evals, Om_S, Om_T = _planted(seed=1)
    mirrored = fmaps.fit_functional_map(A_S, A_T, evals, evals, -Om_S, Om_T, w_orient=1.0)
    assert np.abs(mirrored - C0).max() > 1e-2
