"""refine_extrinsic: a region pushed several edges off comes back; the normal test skips a touching part."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from corr_core.correspondence.dense import measures, mesh_basis, refine_extrinsic
from corr_core.correspondence.dense.nearest import PointTree, VertexNeighbourhoods, nearest_compatible

FAST = {"n_patches": 120, "rounds": 5}


def _slid_region(S, T, offset_edges: float = 5.0):
    """The true map with a geodesic disc (radius 0.12 sqrt(area)) of the torso sent ``offset_edges`` mean edge
    lengths sideways on the target: (p2p (n,) int, region (r,) int)."""
    centre = int(np.argmin(np.linalg.norm(S.V - np.array([0.0, 1.15, 0.2]), axis=1)))
    region = np.flatnonzero(S.distances([centre])[0] < 0.12)
    edge = np.linalg.norm(T.V[T.F[:, 0]] - T.V[T.F[:, 1]], axis=1).mean()
    p2p = np.arange(S.n)
    p2p[region] = cKDTree(T.V).query(T.V[region] + np.array([offset_edges * edge, 0.0, 0.0]))[1]
    return p2p, region


def _error(T, p2p, vertices):
    return float(measures.dense_errors(T.V, T.F, {"m": p2p}, np.arange(T.n), vertices=vertices)["m"].mean())


def test_refine_extrinsic_brings_back_a_region_slid_several_edges(pair):
    S, T = pair
    p2p, region = _slid_region(S, T)
    before = _error(T, p2p, region)
    fixed = refine_extrinsic(S, T, p2p, **FAST)
    local_only = refine_extrinsic(S, T, p2p, n_candidates=8, **FAST)   # older rule: stay near the current image
    after, after_local = _error(T, fixed, region), _error(T, local_only, region)
    assert after < 0.3 * before, (before, after)
    assert after < after_local, (after, after_local)


def test_refine_extrinsic_keeps_the_true_map(pair):
    S, T = pair
    kept = refine_extrinsic(S, T, np.arange(S.n), **FAST)
    edge = np.linalg.norm(T.V[T.F[:, 0]] - T.V[T.F[:, 1]], axis=1).mean() / T.scale
    assert _error(T, kept, np.arange(0, S.n, 7)) < 0.5 * edge        # most vertices stay exactly where they are


def test_nearest_compatible_skips_a_part_facing_the_other_way():
    """Two sheets 0.1 apart facing each other (like a thigh touching the other thigh): a point just below the
    upper sheet with an upward normal belongs to the lower sheet, whose normals point up."""
    g = np.stack(np.meshgrid(np.linspace(0, 1, 11), np.linspace(0, 1, 11)), -1).reshape(-1, 2)
    lower = np.column_stack([g, np.zeros(len(g))])
    upper = np.column_stack([g, np.full(len(g), 0.1)])
    V = np.vstack([lower, upper])
    N = np.vstack([np.tile([0.0, 0.0, 1.0], (len(g), 1)), np.tile([0.0, 0.0, -1.0], (len(g), 1))])
    P, NP = np.array([[0.5, 0.5, 0.08]]), np.array([[0.0, 0.0, 1.0]])
    ids, d = nearest_compatible(cKDTree(V), N, P, NP, min_cos=0.5)
    assert ids[0] < len(g) and np.isclose(d[0], 0.08)
    ids, d = nearest_compatible(cKDTree(V), N, P, -NP, min_cos=0.5, k=4)
    assert ids[0] >= len(g)


def test_nearest_compatible_answers_as_the_search_among_k_for_every_point():
    """The two-nearest shortcut changes no answer: agreeing and disagreeing normals, duplicated vertices (equal
    distances: the search among k decides), none compatible among k (inf), k = 1."""
    from corr_core.correspondence.dense.nearest import _nearest_compatible_among

    rng = np.random.default_rng(2)
    V = rng.normal(size=(400, 3))
    V = np.vstack([V, V[:40]])                                   # 40 duplicated vertices
    N = rng.normal(size=(len(V), 3))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    P = np.vstack([V[:60], V[rng.integers(0, len(V), 300)] + 0.05 * rng.normal(size=(300, 3))])
    NP = N[np.r_[0:60, rng.integers(0, len(V), 300)]] + 0.8 * rng.normal(size=(360, 3))
    # the refinement's tree, and cKDTree, whose order of equidistant points changes with k (the tie check matters)
    for tree in (PointTree(V), cKDTree(V)):
        for min_cos, k in ((0.0, 8), (0.9, 3), (0.0, 1)):
            ids, d = nearest_compatible(tree, N, P, NP, min_cos=min_cos, k=k)
            want_ids, want_d = _nearest_compatible_among(tree, N, P, NP, min_cos, k)
            assert np.array_equal(ids, want_ids) and np.array_equal(d, want_d)
        assert np.isinf(nearest_compatible(tree, N, P, NP, min_cos=0.9, k=3)[1]).any()


def test_point_tree_answers_as_scipy_ckdtree():
    """Distances and ids of cKDTree's query, bit for bit, for k = 1 (1-D results) and k > 1 (nearest first), k
    clipped to the point count; int64 ids; a bad point set is refused by name."""
    rng = np.random.default_rng(4)
    V, P = rng.normal(size=(500, 3)), rng.normal(size=(200, 3))
    tree, reference = PointTree(V), cKDTree(V)
    for k in (1, 2, 8):
        (d, ids), (d_ref, ids_ref) = tree.query(P, k=k), reference.query(P, k=k)
        assert ids.dtype == np.int64 and d.shape == ids.shape == ids_ref.shape
        assert np.array_equal(ids, ids_ref) and np.array_equal(d, d_ref)
    assert PointTree(V[:3]).query(P, k=8)[1].shape == (200, 3)
    with pytest.raises(ValueError, match="PointTree"):
        PointTree(V[:, :2])


def test_vertex_neighbourhoods_are_the_k_d_tree_rows_each_found_once():
    """The kept rows equal a fresh query of the same vertices, bit for bit, in a second call that asks for old
    and new vertices (repeats included); only vertices never asked for are queried; k is clipped to the count."""
    rng = np.random.default_rng(3)
    V = rng.random((400, 3))
    V[7] = V[8]                                              # a duplicate vertex: ties keep the tree's order
    table = VertexNeighbourhoods(V, 12)
    queried, tree = [], table._tree

    class CountingTree:
        def query(self, P, k):
            queried.append(len(P))
            return tree.query(P, k=k)
    table._tree = CountingTree()
    first, second = rng.integers(0, 400, 300), np.concatenate([rng.integers(0, 400, 200), [7, 8, 7]])
    for ids in (first, second):
        assert np.array_equal(table.of(ids), PointTree(V).query(V[ids], k=12)[1])
    assert queried == [len(np.unique(first)), len(np.setdiff1d(second, first))]
    assert VertexNeighbourhoods(V[:5], 12).of(np.arange(5)).shape == (5, 5)


def test_refine_map_runs_the_named_steps_in_order_and_rejects_unknown_ones(pair):
    from corr_core.correspondence.dense import refine_map, refine_spectral

    S, T = pair
    p2p, _ = _slid_region(S, T)
    both = refine_map(S, T, p2p, "extrinsic+spectral", {"extrinsic": FAST})
    assert np.array_equal(both, refine_spectral(S, T, refine_extrinsic(S, T, p2p, **FAST)))
    assert np.array_equal(refine_map(S, T, p2p, None), p2p) and np.array_equal(refine_map(S, T, p2p, "none"), p2p)
    with pytest.raises(ValueError, match="unknown refinement step 'smooth'"):
        refine_map(S, T, p2p, "extrinsic+smooth")


def test_refine_plan_reads_every_form_into_the_same_typed_steps():
    from corr_core.correspondence.dense import RefineStep, refine_plan

    options = {"extrinsic": {"n_patches": 50}, "deform": {"stiffness": 0.02}}
    plan = refine_plan("extrinsic+spectral", options)
    assert plan == (RefineStep("extrinsic", {"n_patches": 50}), RefineStep("spectral"))   # deform's options unused
    assert refine_plan(["extrinsic", "spectral"], options) == plan
    assert refine_plan([RefineStep("extrinsic"), "spectral"], options) == plan               # options fill a step in
    own = refine_plan([RefineStep("deform", {"stiffness": 0.05})], options)
    assert own == (RefineStep("deform", {"stiffness": 0.05}),)                               # a step's own win
    assert refine_plan(None) == () and refine_plan("none", options) == ()


@pytest.mark.parametrize("refine, options, message", [
    ("extrinsic+smoth", None, "unknown refinement step 'smoth'"),
    ("extrinsic", {"extrinsic": {"n_patchez": 50}}, r"step 'extrinsic': unknown option\(s\) \['n_patchez'\]"),
    ("extrinsic", {"extrinsc": {"n_patches": 50}}, r"name no refinement step: \['extrinsc'\]"),
    ([3], None, "a refinement step is a name"),
    (7, None, "refine must be None"),
])
def test_refine_plan_names_a_misspelt_step_or_option(refine, options, message):
    from corr_core.correspondence.dense import refine_plan

    with pytest.raises(ValueError, match=message):
        refine_plan(refine, options)


def test_dense_map_rejects_a_misspelt_refinement_before_any_work(monkeypatch):
    import corr_core.correspondence.dense as dense

    def no_work(*args, **kwargs):
        raise AssertionError("a basis was computed before the refinement was checked")

    monkeypatch.setattr(dense, "mesh_basis", no_work)
    V = np.eye(3)
    with pytest.raises(ValueError, match="unknown option"):
        dense.dense_map(V, np.array([[0, 1, 2]]), V, np.array([[0, 1, 2]]), refine="deform",
                        refine_options={"deform": {"stifness": 0.1}})


def _turned_map(S, T):
    """Each template vertex -> the target vertex nearest its position turned 180 degrees about the vertical axis
    through the target's centre (left <-> right and front <-> back: the orientation-preserving near-symmetry of a
    body); with T a posed copy of S this is the wrong hypothesis map_automatic can rank first."""
    c = T.V.mean(axis=0)
    turned = (T.V - c) * np.array([-1.0, 1.0, -1.0]) + c
    return cKDTree(T.V).query(turned)[1]


def test_map_distortion_is_zero_for_a_similarity_and_higher_for_the_turn(pair):
    from corr_core.correspondence.dense import map_distortion

    S, T = pair
    scaled = mesh_basis(2.5 * S.V, S.F, k=10, n_samples=200)
    assert map_distortion(S, scaled, np.arange(S.n)) == pytest.approx(0.0, abs=1e-12)
    assert map_distortion(S, T, _turned_map(S, T)) > 1.2 * map_distortion(S, T, np.arange(S.n))


def test_map_distortion_of_the_true_map_stays_low_on_a_coarser_or_finer_mesh(pair):
    """Measured on the coarser mesh's edges, the true map onto a decimated copy (about half the vertices) and the
    true map from that copy onto the full mesh score within 3x the same-triangulation distortion; on the finer
    mesh's edges the quantization of the images by the coarse mesh alone gave 6.5x."""
    from corr_core.correspondence.dense import map_distortion
    from corr_core.generate import humanoid

    S, T = pair
    same = map_distortion(S, T, np.arange(S.n))
    V_coarse, F_coarse, truth = humanoid.remesh(T.V, T.F, "decimated")
    coarse = mesh_basis(V_coarse, F_coarse, k=10, n_samples=200)
    assert coarse.n < 0.6 * T.n
    assert map_distortion(S, coarse, truth) < 3 * same
    assert map_distortion(coarse, T, cKDTree(T.V).query(coarse.V)[1]) < 3 * same


def test_refine_best_keeps_the_less_distorted_hypothesis_whatever_its_rank(pair):
    from corr_core.correspondence.dense import map_distortion, refine_best

    S, T = pair
    truth, turned = np.arange(S.n), _turned_map(S, T)
    for maps, right in (([turned, truth], 1), ([truth, turned], 0)):
        best = refine_best(S, T, maps, refine=None)
        assert best.index == right and np.array_equal(best.p2p, maps[right])
        assert best.distortions == tuple(map_distortion(S, T, m) for m in maps)
        assert 0 < best.confidence <= 1 and best.margin > 0
    with pytest.raises(ValueError, match="no hypothesis"):
        refine_best(S, T, [])


def test_confidence_is_low_when_two_hypotheses_refine_alike_and_nan_for_one():
    from corr_core.correspondence.dense import BestMap
    from corr_core.correspondence.dense.refine import CONFIDENT_MARGIN

    p2p = np.zeros(3, dtype=np.int64)
    assert BestMap(p2p, 0, (0.20, 0.20)).confidence == 0.0                  # a tie: no idea which is right
    assert BestMap(p2p, 1, (0.30, 0.20)).confidence == 1.0                  # 50 % margin: sure
    half = BestMap(p2p, 0, (0.20, 0.20 * (1 + CONFIDENT_MARGIN / 2), 0.5))  # the runner-up decides, not the last
    assert half.confidence == pytest.approx(0.5) and half.margin == pytest.approx(CONFIDENT_MARGIN / 2)
    assert np.isnan(BestMap(p2p, 0, (0.2,)).confidence)


def test_a_step_written_with_a_question_mark_is_kept_only_where_it_lowers_the_distortion(pair, monkeypatch):
    from corr_core.correspondence.dense import refine

    S, T = pair
    truth, turned = np.arange(S.n), _turned_map(S, T)
    monkeypatch.setitem(refine.REFINE_STEPS, "to_turn", lambda source, target, p2p: turned)
    monkeypatch.setitem(refine.REFINE_STEPS, "to_truth", lambda source, target, p2p: truth)
    guarded, plain = refine.refine_plan("to_turn?+to_truth?"), refine.refine_plan(["to_turn"])
    assert [(s.name, s.only_if_lower) for s in guarded] == [("to_turn", True), ("to_truth", True)]
    assert guarded == refine.refine_plan([refine.RefineStep("to_turn", only_if_lower=True), "to_truth?"])
    assert np.array_equal(refine.refine_map(S, T, truth, guarded[:1]), truth)     # more distorted: not taken
    assert np.array_equal(refine.refine_map(S, T, truth, plain), turned)          # without "?": taken
    assert np.array_equal(refine.refine_map(S, T, turned, guarded[1:]), truth)    # less distorted: taken


def test_refine_best_drops_a_hypothesis_surely_beaten_after_the_first_step(pair, monkeypatch):
    from corr_core.correspondence.dense import refine

    S, T = pair
    truth, turned = np.arange(S.n), _turned_map(S, T)
    later = []
    monkeypatch.setitem(refine.REFINE_STEPS, "first", lambda source, target, p2p: p2p)
    monkeypatch.setitem(refine.REFINE_STEPS, "later", lambda source, target, p2p: later.append(p2p) or p2p)
    d_truth, d_turned = refine.map_distortion(S, T, truth), refine.map_distortion(S, T, turned)
    assert d_turned > (1 + refine.DROP_MARGIN) * d_truth                       # the fixture's turn: surely beaten
    best = refine.refine_best(S, T, [turned, truth], ["first", "later"])
    assert best.index == 1 and len(later) == 1 and np.array_equal(later[0], truth)   # the turn got no later step
    assert best.dropped == (True, False) and best.step_distortions == ((d_turned,), (d_truth, d_truth))
    assert best.margin == pytest.approx((d_turned - d_truth) / d_truth) and best.confidence == 1.0
    later.clear()
    close = refine.refine_best(S, T, [truth, truth.copy()], ["first", "later"])   # a tie: both refined to the end
    assert len(later) == 2 and close.dropped == () and close.confidence == 0.0
    later.clear()
    single = refine.refine_best(S, T, [turned], ["first", "later"])          # one hypothesis: every step
    assert len(later) == 1 and single.distortions == (d_turned,)


def test_the_first_round_and_the_rest_of_the_extrinsic_step_give_its_map_bit_for_bit(pair):
    from corr_core.correspondence.dense import refine

    S, T = pair
    start = np.roll(np.arange(S.n), 7)                             # off by a few vertices everywhere
    step = refine.RefineStep("extrinsic", {"n_patches": 20, "patch_size": 16})
    one, rest = refine.first_round_split(step)
    assert one.options["rounds"] == 1 and rest.options["rounds"] == 4 and one.options["n_patches"] == 20
    after_one = one.run(S, T, start)
    assert not np.array_equal(after_one, start)                    # the first round did something
    assert np.array_equal(rest.run(S, T, after_one), step.run(S, T, start))
    for other in (refine.RefineStep("deform"), refine.RefineStep("extrinsic?"),
                  refine.RefineStep("extrinsic", {"rounds": 1})):
        assert refine.first_round_split(other) is None


def test_refine_best_drops_a_hypothesis_surely_beaten_after_the_first_round(pair, monkeypatch):
    """Beyond EARLY_DROP_MARGIN after the first round of the extrinsic step, a hypothesis gets no more of it; the
    kept map is the one refining both to the end keeps, and the margin compares the two after that round."""
    from corr_core.correspondence.dense import refine

    S, T = pair
    truth, turned = np.arange(S.n), _turned_map(S, T)
    calls = []

    def extrinsic(source, target, p2p, *, rounds=5):
        calls.append((p2p.copy(), rounds))
        return p2p

    monkeypatch.setitem(refine.REFINE_STEPS, "extrinsic", extrinsic)
    monkeypatch.setitem(refine.REFINE_STEPS, "later", lambda source, target, p2p: p2p)
    d_truth, d_turned = refine.map_distortion(S, T, truth), refine.map_distortion(S, T, turned)
    assert d_turned > (1 + refine.EARLY_DROP_MARGIN) * d_truth                   # surely beaten after one round
    best = refine.refine_best(S, T, [turned, truth], ["extrinsic", "later"])
    assert [(np.array_equal(m, truth), r) for m, r in calls] == [(False, 1), (True, 1), (True, 4)]
    assert best.index == 1 and np.array_equal(best.p2p, truth)
    assert best.dropped == (True, False) and best.step_distortions == ((), (d_truth, d_truth))
    assert best.early == (d_turned, d_truth) and best.distortions == (d_turned, d_truth)
    assert best.margin == pytest.approx((d_turned - d_truth) / d_truth) and best.confidence == 1.0
    calls.clear()
    both = refine.refine_best(S, T, [turned, truth], ["extrinsic", "later"], early_margin=float("inf"))
    assert [r for _, r in calls] == [1, 1, 4, 4] and np.array_equal(both.p2p, best.p2p) and both.index == 1
    calls.clear()                               # given points are kept after every part: the step is not split
    points = (S.samples[:3], S.samples[:3])
    held = refine.refine_best(S, T, [turned, truth], ["extrinsic", "later"], points=points)
    assert [r for _, r in calls] == [5, 5] and held.early == () and held.index == 1


def test_surviving_hypotheses_and_the_margin_of_a_dropped_one():
    from corr_core.correspondence.dense import BestMap, surviving_hypotheses

    assert surviving_hypotheses([0.2, 0.259, 0.261, float("inf")]) == [0, 1]          # DROP_MARGIN 0.3
    assert surviving_hypotheses([0.2, 0.219, 0.221], drop_margin=0.1) == [0, 1]
    assert surviving_hypotheses([float("inf"), float("inf")]) == [0, 1]      # nothing to tell them apart
    p2p = np.zeros(3, dtype=np.int64)
    dropped = BestMap(p2p, 0, (0.20, 0.26), dropped=(False, True), step_distortions=((0.25, 0.20), (0.26,)))
    assert dropped.margin == pytest.approx(0.04) and dropped.confidence == pytest.approx(0.4)   # same-step compare
    later = BestMap(p2p, 0, (0.18, 0.25), dropped=(False, True), step_distortions=((0.2, 0.2, 0.18), (0.2, 0.25)))
    assert later.margin == pytest.approx(np.sqrt(0.2 * 0.25) / 0.2 - 1)          # scores over the same two steps
    early = BestMap(p2p, 1, (0.5, 0.2), dropped=(True, False), step_distortions=((), (0.2, 0.2)), early=(0.5, 0.25))
    assert early.margin == pytest.approx(1.0)                               # after the first round: 0.5 / 0.25


def test_surviving_after_step_drops_on_the_first_distortion_then_on_the_score_so_far():
    from corr_core.correspondence.dense import surviving_after_step
    from corr_core.correspondence.dense.refine import DROP_MARGIN, LATER_DROP_MARGIN

    assert LATER_DROP_MARGIN < DROP_MARGIN
    first = [[0.20], [0.25], [0.27]]                                  # after step 1: 1.25 kept, 1.35 dropped
    assert surviving_after_step(first, [0, 1, 2]) == [0, 1]
    second = [[0.20, 0.20], [0.25, 0.20], [0.27]]               # scores so far 0.2 and 0.2236 (x1.118): kept
    assert surviving_after_step(second, [0, 1]) == [0, 1]
    second[1][1] = 0.25                                          # 0.25 (x1.25): dropped after a later step
    assert surviving_after_step(second, [0, 1]) == [0]
    assert surviving_after_step(second, [1]) == [1]              # a lone hypothesis always goes on
    with pytest.raises(ValueError, match="different numbers of steps"):
        surviving_after_step(second, [0, 2])


def test_refine_best_drops_a_hypothesis_beaten_after_a_later_step_before_the_last(pair, monkeypatch):
    """A hypothesis close after the first step but clearly beaten after the second gets no last step; the margin
    compares the two on the steps both got."""
    from corr_core.correspondence.dense import refine

    S, T = pair
    truth, turned = np.arange(S.n), _turned_map(S, T)
    near = truth.copy()
    near[:3] = near[3]                                           # nearly the truth after the first step
    last = []
    monkeypatch.setitem(refine.REFINE_STEPS, "first", lambda source, target, p2p: p2p)
    monkeypatch.setitem(refine.REFINE_STEPS, "mid",
                        lambda source, target, p2p: p2p if np.array_equal(p2p, truth) else turned)
    monkeypatch.setitem(refine.REFINE_STEPS, "last", lambda source, target, p2p: last.append(p2p) or p2p)
    d_truth, d_near, d_turned = (refine.map_distortion(S, T, m) for m in (truth, near, turned))
    assert d_near <= (1 + refine.DROP_MARGIN) * d_truth                        # survives the first step
    assert np.sqrt(d_near * d_turned) > (1 + refine.LATER_DROP_MARGIN) * d_truth
    best = refine.refine_best(S, T, [near, truth], ["first", "mid", "last"])
    assert best.index == 1 and len(last) == 1 and np.array_equal(last[0], truth)
    assert best.dropped == (True, False) and best.step_distortions == ((d_near, d_turned), (d_truth,) * 3)
    assert best.margin == pytest.approx(np.sqrt(d_near * d_turned) / d_truth - 1)
    last.clear()
    both = refine.refine_best(S, T, [near, truth], ["first", "mid", "last"], later_margin=10.0)
    assert len(last) == 2 and both.dropped == () and both.index == 1


def test_points_agreement_counts_the_given_points_a_map_keeps(pair):
    from corr_core.correspondence.dense import points_agreement

    S, T = pair
    points = S.samples[:6]
    assert points_agreement(T, np.arange(S.n), (points, points)) == 1.0
    assert points_agreement(T, _turned_map(S, T), (points, points)) <= 0.5


def _thin_plate(n: int = 17, thickness: float = 0.02):
    """A closed plate 1 x 1 x ``thickness`` (top and bottom grids of n x n vertices, joined at the rim), faces
    oriented outward: (V (2 n^2, 3), F, top (n^2,) bool mask)."""
    g = np.linspace(0.0, 1.0, n)
    x, y = np.meshgrid(g, g, indexing="ij")
    grid = np.column_stack([x.ravel(), y.ravel()])
    V = np.vstack([np.column_stack([grid, np.full(n * n, thickness)]), np.column_stack([grid, np.zeros(n * n)])])
    idx = np.arange(n * n).reshape(n, n)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    top = np.vstack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    bottom = top[:, ::-1] + n * n
    rim = np.concatenate([idx[:, 0], idx[-1, 1:], idx[::-1, -1][1:], idx[0, ::-1][1:-1]])   # boundary loop
    a, b = rim, np.roll(rim, -1)
    sides = np.vstack([np.column_stack([a, a + n * n, b]), np.column_stack([b, a + n * n, b + n * n])])
    F = np.vstack([top, bottom, sides])
    return V, F, np.arange(len(V)) < n * n


def test_refine_extrinsic_keeps_each_side_of_a_thin_part():
    """The normal test, through the whole refinement: a thin plate (0.02 thick, edges 0.0625) whose top is
    re-sampled on the target (each inner top vertex moved up to 0.45 edge along the plate, at random, so no rigid
    patch motion undoes it). For many top vertices the nearest target vertex is then on the bottom, right below;
    only the normal test (the bottom faces the other way) keeps the map on the top. Accepting any normal in the
    final assignment sends a large part of the top to the bottom."""
    V, F, top = _thin_plate()
    # keep the orientation test honest: the top faces up, the bottom down
    n_top = np.cross(V[F[0, 1]] - V[F[0, 0]], V[F[0, 2]] - V[F[0, 0]])
    assert n_top[2] > 0
    V_t = V.copy()
    inner = top & (V[:, 0] > 0) & (V[:, 0] < 1) & (V[:, 1] > 0) & (V[:, 1] < 1)
    jitter = np.random.default_rng(0).uniform(-0.45, 0.45, (int(inner.sum()), 2)) / 16
    V_t[inner, :2] += jitter
    S, T = mesh_basis(V, F, k=10, n_samples=300), mesh_basis(V_t, F, k=10, n_samples=300)
    out = refine_extrinsic(S, T, np.arange(S.n), n_patches=40, patch_size=32, rounds=3)
    on_top = top[out[top]]
    assert on_top.mean() > 0.95, on_top.mean()


def test_best_with_points_takes_a_less_distorted_map_only_if_it_keeps_the_given_points(pair):
    from corr_core.correspondence.dense import best_with_points

    S, T = pair
    truth, turned = np.arange(S.n), _turned_map(S, T)
    points = S.samples[:6]
    kept = best_with_points(S, T, [turned, truth], (points, points))          # the true map keeps the points
    assert kept.index == 1 and np.array_equal(kept.p2p, truth)
    assert best_with_points(S, T, [truth, turned], (points, points)).index == 0
    lying = best_with_points(S, T, [turned, truth], (points, _turned_map(S, T)[points]))   # points given turned
    assert lying.index == 0 and np.isinf(lying.distortions[1])             # the other map does not keep them


def test_with_alternative_keeps_the_alternative_only_when_best_with_points_would(pair, monkeypatch):
    from corr_core.correspondence.dense import refine
    from corr_core.correspondence.dense.basis import map_to_original

    S, T = pair
    truth, turned = np.arange(S.n), _turned_map(S, T)
    points = S.samples[:6]
    from_points = refine.BestMap(turned, 0, (refine.map_distortion(S, T, turned),))
    scored = []
    monkeypatch.setattr(refine, "map_distortion", lambda s, t, m: scored.append(m) or 0.0)
    kept = refine.with_alternative(S, T, from_points, map_to_original(S, T, truth), (points, points))
    assert kept.index == 1 and np.array_equal(kept.p2p, truth)
    assert len(scored) == 1 and kept.distortions[0] == from_points.distortions[0]   # map 0's distortion reused


def test_a_kept_alternative_is_held_to_the_points(pair, monkeypatch):
    """With the plan that refined the map from the points, ``with_alternative`` runs the plan's registration on
    the alternative it keeps, with the points held (``hold_points``); an alternative it does not keep is not
    refined at all."""
    from corr_core.correspondence.dense import refine
    from corr_core.correspondence.dense.basis import map_to_original

    S, T = pair
    truth, turned = np.arange(S.n), _turned_map(S, T)
    points = (S.samples[:4], truth[S.samples[:4]].copy())
    points[1][0] = int(np.argsort(np.linalg.norm(T.V - T.V[points[1][0]], axis=1))[1])   # a vertex off the truth
    from_points = refine.BestMap(turned, 0, (np.inf,))
    held = refine.with_alternative(S, T, from_points, map_to_original(S, T, truth), points, refine="spectral+deform")
    assert held.index == 1 and np.array_equal(held.p2p[points[0]], points[1])
    assert np.array_equal(held.p2p, refine.hold_points(S, T, truth, "spectral+deform", points))
    runs = []
    monkeypatch.setattr(refine.RefineStep, "run", lambda *a, **k: runs.append(a) or a[3])
    refine.with_alternative(S, T, refine.BestMap(truth, 0, (0.0,)), map_to_original(S, T, turned), points,
                            refine="deform")
    assert not runs                                                        # turned keeps no point: not refined


def test_both_maps_are_held_once_more_and_the_less_distorted_held_map_is_kept(pair, monkeypatch):
    """With a plan, the map from the points and an alternative that keeps them are both held once more
    (``hold_points``) and compared held: comparing the map from the points as it came with a held alternative,
    or the two as they came, kept on the default pipeline's poses 2 and 6 a map from the points less distorted
    by a hair but less accurate than the automatic one. A tie keeps the map from the points."""
    from corr_core.correspondence.dense import refine
    from corr_core.correspondence.dense.basis import map_to_original

    S, T = pair
    truth = np.arange(S.n)
    points = (S.samples[:4], truth[S.samples[:4]].copy())
    from_points = truth.copy()
    from_points[S.samples[10]] = T.samples[11]                       # another map that keeps the points too
    held_ones: list[np.ndarray] = []

    def hold(source, target, p2p, plan, pts):
        held_ones.append(np.asarray(p2p))
        return np.asarray(p2p) + 0                                   # a new array: "held"

    for held_scores, kept_index in (((0.2, 0.1), 1), ((0.1, 0.2), 0), ((0.1, 0.1), 0)):
        held_ones.clear()
        scores = iter(held_scores)
        monkeypatch.setattr(refine, "hold_points", hold)
        monkeypatch.setattr(refine, "map_distortion", lambda s, t, m: next(scores))
        kept = refine.with_alternative(S, T, refine.BestMap(from_points, 0, (0.0,)), map_to_original(S, T, truth),
                                       points, refine="deform")
        assert [np.array_equal(m, w) for m, w in zip(held_ones, (from_points, truth))] == [True, True]
        assert kept.index == kept_index and kept.distortions == held_scores, (held_scores, kept)
        assert np.array_equal(kept.p2p, (from_points, truth)[kept_index])


def test_map_to_local_inverts_map_to_original(pair):
    from corr_core.correspondence.dense.basis import map_to_local, map_to_original

    S, T = pair
    p2p = _turned_map(S, T)
    assert np.array_equal(map_to_local(S, T, map_to_original(S, T, p2p)), p2p)
    with pytest.raises(ValueError, match="vertex map has shape"):
        map_to_local(S, T, p2p[:-1])


def test_the_choice_weighs_every_step_not_only_the_last():
    """A wrong map that the later steps smooth to a slightly lower last distortion than the right one's, after being
    clearly more distorted at the first step (seed 13's decimated pose, docs/dense.md "Confidence"), is not kept."""
    from corr_core.correspondence.dense.refine import best_refined, refinement_score

    maps = [np.zeros(3, dtype=np.int64), np.ones(3, dtype=np.int64)]
    turned, right = [0.2206, 0.2156, 0.1945], [0.2074, 0.2193, 0.1972]       # after each step of the plan
    best = best_refined(maps, [turned, right])
    assert best.index == 1 and best.distortions == (0.1945, 0.1972)
    assert best.scores == pytest.approx([refinement_score(turned), refinement_score(right)])
    assert best.margin == pytest.approx(refinement_score(turned) / refinement_score(right) - 1)
    assert refinement_score([0.3]) == 0.3 and refinement_score([0.2, 0.05]) == pytest.approx(0.1)
    assert refinement_score([0.2, float("inf")]) == float("inf") and refinement_score([0.0, 0.2]) == 0.0


def test_refine_best_scores_every_surviving_hypothesis_over_its_steps(pair, monkeypatch):
    from corr_core.correspondence.dense import refine

    S, T = pair
    truth, turned = np.arange(S.n), _turned_map(S, T)
    monkeypatch.setitem(refine.REFINE_STEPS, "first", lambda source, target, p2p: p2p)
    monkeypatch.setitem(refine.REFINE_STEPS, "to_truth", lambda source, target, p2p: truth)
    d_truth, d_turned = refine.map_distortion(S, T, truth), refine.map_distortion(S, T, turned)
    best = refine.refine_best(S, T, [turned, truth], ["first", "to_truth"], drop_margin=10.0)
    # both end at the true map; the one that started as the true map scored better over the steps
    assert best.index == 1 and best.distortions == (d_truth, d_truth) and best.dropped == ()
    assert best.scores == pytest.approx([np.sqrt(d_turned * d_truth), d_truth])


def test_point_to_plane_partners_lie_on_the_surface_between_the_vertices():
    """Points on a coarse unit sphere (200 vertices, edges about 0.25) paired with their nearest vertex: the vertex
    itself is about a third of an edge away, its tangent-plane projection (``partners="plane"``) only the sphere's
    curvature away, so a patch is pulled to the surface, not to the vertices (what makes the extrinsic step hold on
    a target coarser than the template)."""
    from corr_core.correspondence.dense.refine import _icp_targets
    from tests.helpers import sphere

    V_t = sphere(200)[0]
    T = type("Target", (), {"V": V_t})()
    moved = sphere(5000)[0][None]            # (1, 5000, 3), on the true surface
    j = cKDTree(V_t).query(moved[0])[1][None]
    to_vertex = np.linalg.norm(_icp_targets(T, V_t, moved, j, "vertex") - moved, axis=2).mean()
    on_plane = _icp_targets(T, V_t, moved, j, "plane")
    to_plane = np.linalg.norm(on_plane - moved, axis=2).mean()
    assert to_vertex > 0.05 and to_plane < 0.1 * to_vertex, (to_vertex, to_plane)
    assert np.allclose(np.einsum("bpc,bpc->bp", on_plane - V_t[j], V_t[j]), 0.0)   # in the tangent plane


def test_refine_extrinsic_names_a_misspelt_partner_rule(pair):
    S, T = pair
    with pytest.raises(ValueError, match="partners must be one of"):
        refine_extrinsic(S, T, np.arange(S.n), partners="planar", **FAST)


def test_second_opinion_replaces_a_map_with_a_slid_region_and_keeps_the_true_one(pair):
    """The map made from the template's feature points and their images (right under both maps: the slid disc is
    on the torso) replaces the map with the slid region, the less distorted; the true map stays, as it is."""
    from corr_core.correspondence.dense import BestMap, map_distortion
    from corr_core.correspondence.dense.refine import second_opinion

    S, T = pair
    plan, options, ks = "extrinsic", {"extrinsic": FAST}, {"k_init": 10, "k_end": 20}
    slid, region = _slid_region(S, T)
    best = BestMap(slid, 1, (0.5, map_distortion(S, T, slid)))
    out = second_opinion(S, T, best, plan, options, **ks)
    assert not np.array_equal(out.p2p, slid)
    assert map_distortion(S, T, out.p2p) < map_distortion(S, T, slid)
    assert _error(T, out.p2p, region) < 0.3 * _error(T, slid, region)
    assert (out.index, out.distortions) == (best.index, best.distortions)
    truth = BestMap(np.arange(S.n), 0, (0.1,))
    assert second_opinion(S, T, truth, plan, options, **ks) is truth


def test_dense_map_asks_for_the_second_opinion_in_the_automatic_mode_only(monkeypatch):
    from corr_core.correspondence import dense
    from corr_core.generate.humanoid import make_humanoid_rest

    calls = []
    monkeypatch.setattr(dense, "refine_second_opinion", lambda S, T, best, *a, **k: calls.append(k) or best)
    V, F = make_humanoid_rest(grid_step=0.09)
    common = {"k": 12, "k_init": 8, "refine": None}
    plain = dense.dense_map(V, F, V, F, **common)
    asked = dense.dense_map(V, F, V, F, second_opinion=True, **common)
    assert calls == [{"k_init": 8, "k_end": 12}] and np.array_equal(plain, asked)
    dense.dense_map(V, F, V, F, [0, 1, 2], [0, 1, 2], second_opinion=True, **common)
    assert len(calls) == 1                                   # given points: no second opinion
