"""Shared fixture of the dense-refinement tests: a small generated humanoid and one posed copy (same vertices)."""
from __future__ import annotations

import numpy as np
import pytest

from corr_core.correspondence.dense import mesh_basis
from corr_core.generate import humanoid


@pytest.fixture(scope="module")
def pair():
    """(template basis, target basis): the rest body (grid 0.045) and a random pose of it, k = 20, 600 samples;
    the true map is the identity."""
    V, F = humanoid.make_humanoid_rest(grid_step=0.045)
    W, _ = humanoid.skinning_weights(V, F)
    Vp = humanoid.pose_mesh(V, W, humanoid.random_pose(np.random.default_rng(5)))
    return mesh_basis(V, F, k=20, n_samples=600), mesh_basis(Vp, F, k=20, n_samples=600)
