"""The automatic initial map's scoring parts (``init``): scale-invariant assignment ranking, the WKS agreement of
a map, the chirality agreement of a map, and the choice among candidate maps."""
from __future__ import annotations

import numpy as np
import pytest

from corr_core.correspondence.dense import fmaps, init, mesh_basis
from tests.helpers import sphere


@pytest.fixture(scope="module")
def ellipsoid():
    """An ellipsoid with three different radii, its basis, and the basis of its mirror image (y -> -y)."""
    V, F = sphere(n=800)
    V = V * np.array([1.0, 0.6, 0.35])
    Vm, Fm = V * np.array([1.0, -1.0, 1.0]), F[:, ::-1].copy()
    return V, F, mesh_basis(V, F, k=30, n_samples=300), mesh_basis(Vm, Fm, k=30, n_samples=300)


def test_scale_invariant_ranking_finds_the_assignment_of_a_shrunken_copy():
    """Target distances 0.8 x the source's (a bent or thinner body): every assignment then differs by about the
    same amount unless the scale is taken out."""
    rng = np.random.default_rng(2)
    X = rng.normal(size=(5, 3))
    D = np.linalg.norm(X[:, None] - X[None], axis=2)
    perm = np.array([2, 4, 0, 1, 3])
    Dt = np.empty_like(D)
    Dt[np.ix_(perm, perm)] = 0.8 * D
    s, t, cost = init.ranked_assignments(D, Dt, keep=3, scale_invariant=True)[0]
    assert cost == pytest.approx(0.0, abs=1e-12) and np.array_equal(t[s], perm)
    assert init.ranked_assignments(D, Dt, keep=1)[0][2] > 0.05           # without it the true one costs 0.2 x


def test_wks_disagreement_is_zero_for_the_identity_also_on_a_scaled_copy(ellipsoid):
    V, F, B, _ = ellipsoid
    identity = B.samples
    assert init.wks_disagreement(B, B, identity) == pytest.approx(0.0, abs=1e-12)
    big = mesh_basis(1.5 * V, F, k=30, n_samples=300)                  # eigenvalues / 2.25: same after rescaling
    assert init.wks_disagreement(B, big, identity) < 1e-6
    shifted = np.roll(identity, 7)                                     # every sample sent to another one
    assert init.wks_disagreement(B, B, shifted) > 0.02


def test_chirality_agreement_is_positive_for_a_map_and_negative_for_its_mirror(ellipsoid):
    V, F, B, Bm = ellipsoid
    pts = np.array([0, 100, 400, 650])
    chir = fmaps.chirality_functions(B, B.distances(pts).T)
    chir_m = fmaps.chirality_functions(Bm, Bm.distances(pts).T)
    identity = B.samples                                               # vertex i -> i (a mirror map onto Bm)
    assert init.chirality_agreement(B, identity, chir, chir) == pytest.approx(1.0)
    assert init.chirality_agreement(B, identity, chir, chir_m) < -0.99


def _candidate(cost: float, chirality: float, wks: float) -> "init.Candidate":
    """A candidate told apart by its ``cost`` (a name here) and scored by chirality and WKS."""
    empty = np.zeros(0, dtype=np.int64)
    return init.Candidate(empty, empty, cost, np.eye(2), empty, chirality=chirality, wks=wks)


def test_ranking_rejects_mirror_and_twisted_maps_then_takes_the_best_wks():
    from dataclasses import replace

    names = {0.0: "mirror", 1.0: "twist", 2.0: "true", 3.0: "turn"}
    cands = [_candidate(0.0, -0.8, 0.010), _candidate(1.0, 0.45, 0.020), _candidate(2.0, 0.80, 0.030),
             _candidate(3.0, 0.78, 0.035)]
    assert [names[c.cost] for c in init.rank_candidates(cands)] == ["true", "turn", "twist", "mirror"]
    all_negative = [replace(c, chirality=-abs(c.chirality) - 0.1) for c in cands]   # twist: -0.55, the highest
    assert names[init.rank_candidates(all_negative)[0].cost] == "twist"   # the one that keeps the orientation most
