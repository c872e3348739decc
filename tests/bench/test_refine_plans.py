"""bench/refine_plans.py: a plan written with ":points" is refined with the sparse points held (as dense_map
refines a map from given points), the same plan without it is not, and each is refine_map's map (a small generated
humanoid)."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def pair():
    """(template basis, target basis): a generated body and a random pose of it (the true map is the identity)."""
    from corr_core.correspondence.dense import mesh_basis
    from corr_core.generate import humanoid

    V, F = humanoid.make_humanoid_rest(grid_step=0.06)
    W, _ = humanoid.skinning_weights(V, F)
    Vp = humanoid.pose_mesh(V, W, humanoid.random_pose(np.random.default_rng(5)))
    return mesh_basis(V, F, k=30, n_samples=300), mesh_basis(Vp, F, k=30, n_samples=300)


def test_a_plan_with_points_holds_them_and_one_without_does_not(pair):
    from bench.refine_plans import HELD, refine_plans
    from corr_core.correspondence.dense import refine

    S, T = pair
    truth = np.arange(S.n)
    points = (np.array([10, 200]), np.array([11, 201]))              # a vertex off the truth on purpose
    plans = ["extrinsic+deform", "extrinsic+deform" + HELD, "extrinsic"]
    out = refine_plans(S, T, truth, plans, points)
    options = {"extrinsic": {"n_patches": 150}}
    assert np.array_equal(out["extrinsic+deform" + HELD][0], refine.refine_map(S, T, truth, "extrinsic+deform",
                                                                                 options, points=points))
    assert np.array_equal(out["extrinsic+deform"][0], refine.refine_map(S, T, truth, "extrinsic+deform", options))
    assert np.array_equal(out["extrinsic+deform" + HELD][0][points[0]], points[1])
    assert not np.array_equal(out["extrinsic+deform"][0][points[0]], points[1])
    assert np.array_equal(out["extrinsic"][0], refine.refine_map(S, T, truth, "extrinsic", options))
