"""bench/dense_cost.py: the timed map is dense_map's, bit for bit, the parts add up to the total, and every
function it wraps is restored afterwards (a small generated humanoid)."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def pair():
    from corr_core.correspondence.dense import mesh_basis
    from corr_core.generate import humanoid

    V, F = humanoid.make_humanoid_rest(grid_step=0.06)
    W, _ = humanoid.skinning_weights(V, F)
    Vp = humanoid.pose_mesh(V, W, humanoid.random_pose(np.random.default_rng(5)))
    lms = humanoid.landmark_vertices(V)
    sparse = np.array([lms[n] for n in humanoid.SPARSE_LANDMARK_NAMES])
    S = mesh_basis(V, F, k=30, n_samples=300)
    return (V, F, S), Vp, F, (sparse, sparse)


@pytest.mark.parametrize("mode", ["sparse", "auto"])
def test_the_timed_map_is_dense_maps_and_the_parts_add_up(pair, mode):
    from bench.dense_cost import PARTS, map_cost
    from corr_core.correspondence.dense import dense_map, init, mesh_basis, refine, zoomout

    template, V, F, sparse = pair
    wrapped = (init.extremities, init.point_features, init.map_from_points, init._zoomout_and_match,
               zoomout.zoomout, refine.map_distortion, dict(refine.REFINE_STEPS))
    p2p, seconds = map_cost(template, V, F, mode, sparse)
    V_s, F_s, S = template
    points = {} if mode == "auto" else {"landmarks_template": sparse[0], "landmarks_target": sparse[1]}
    plain = dense_map(V_s, F_s, V, F, basis_template=S, basis_target=mesh_basis(V, F, k=30, n_samples=300), k=30,
                      **points)
    assert np.array_equal(p2p, plain)
    assert set(seconds) == set(PARTS) | {"total"}
    assert sum(seconds[p] for p in PARTS) == pytest.approx(seconds["total"], abs=1e-9)
    assert all(seconds[p] >= 0 for p in PARTS if p != "other") and seconds["extrinsic"] > 0
    assert (seconds["extremities"] > 0) == (mode == "auto")
    assert (init.extremities, init.point_features, init.map_from_points, init._zoomout_and_match, zoomout.zoomout,
            refine.map_distortion, dict(refine.REFINE_STEPS)) == wrapped               # restored


def test_part_timer_counts_an_inner_call_once():
    from bench.dense_cost import PartTimer

    timer = PartTimer()

    def spin(seconds):
        import time
        t0 = time.process_time()
        while time.process_time() - t0 < seconds:
            pass

    inner = timer.wrap("inner", lambda: spin(0.05))
    outer = timer.wrap("outer", lambda: (spin(0.05), inner()))
    outer()
    assert timer.seconds["inner"] == pytest.approx(0.05, abs=0.03)
    assert timer.seconds["outer"] == pytest.approx(0.05, abs=0.03)               # without the inner call
