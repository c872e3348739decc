"""Mesh pictures with the project's ray caster: colours land where the vertices are, hidden points are told
apart, a dense map pulls colours back, and the figure stages write their files."""
from __future__ import annotations

import numpy as np
import pytest

from corr_core.plotting import meshes as pm


def box_mesh():
    """A unit cube (8 vertices, 12 outward triangles) centred at the origin, scaled to radius 1."""
    V = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) / np.sqrt(3)
    F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return V, F


def test_render_colored_puts_vertex_colours_on_the_visible_side():
    V, F = box_mesh()
    front = V[:, 2] > 0                          # view 0 looks from +z
    colors = np.where(front[:, None], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    image = pm.render_colored(V, F, colors, view=0, n_views=8, size=64, elevation_deg=0.0)
    assert image.shape == (64, 64, 3)
    centre = image[32, 32]
    assert centre[0] > 0.5 and centre[2] < 0.05        # the red front face, not the blue back
    assert np.allclose(image[0, 0], 1.0)               # white background
    back = pm.render_colored(V, F, colors, view=4, n_views=8, size=64, elevation_deg=0.0)   # from -z
    assert back[32, 32, 2] > 0.5 and back[32, 32, 0] < 0.05
    with pytest.raises(ValueError, match="colors must be"):
        pm.render_colored(V, F, colors[:3])


def test_project_vertices_positions_and_visibility():
    V, F = box_mesh()
    xy, visible = pm.project_vertices(V, F, np.arange(8), view=0, n_views=8, size=100, elevation_deg=0.0)
    assert visible.tolist() == (V[:, 2] > 0).tolist()  # front corners visible, back ones hidden
    s = 1 / np.sqrt(3) / pm.MARGIN
    right_top = np.nonzero((V[:, 0] > 0) & (V[:, 1] > 0) & (V[:, 2] > 0))[0][0]
    assert np.allclose(xy[right_top], [(1 + s) * 50, (1 - s) * 50])   # +x right, +y up (row 0 at the top)


def test_pull_back_colors_identity_and_fill():
    V = np.random.default_rng(0).normal(size=(30, 3))
    colors = pm.coordinate_colors(V)
    assert colors.min() >= 0 and colors.max() <= 1
    assert np.allclose(pm.pull_back_colors(colors, np.arange(30), V), colors)
    # everything mapped onto vertex 0: vertex 0 gets the mean colour, the others fill from it
    out = pm.pull_back_colors(colors, np.zeros(30, int), V)
    assert np.allclose(out, colors.mean(0))
    with pytest.raises(ValueError, match="vertex_map"):
        pm.pull_back_colors(colors, np.full(30, 30), V)


def test_figure_stages_write_pictures(tmp_path):
    from shapecorr import figures
    V, F = box_mesh()
    mesh = {"V": V, "F": F, "area": 1.0}
    perm = np.random.default_rng(0).permutation(len(V))            # the same box, vertices in another order
    shuffled = {"V": V[np.argsort(perm)], "F": perm[F], "area": 1.0, "name": "p4.obj"}
    lm = tmp_path / "landmarks.txt"
    lm.write_text("0,a\n7,b\n3,c\n")
    preds = {"p1": {"all": np.array([0, 1, 2])}, "p2": {"all": np.array([1, 0, 2])},
             "p3": {"all": np.array([0, 1, 2]), "no_truth": "different vertex count"},
             "p4": {"all": np.array([0, 1, 2])}}
    out = figures.landmark_figures(mesh, {"t": mesh, "p1": mesh, "p2": mesh, "p3": mesh, "p4": shuffled}, str(lm),
                                   mrf=preds, out_dir=str(tmp_path))
    assert out["figures"] == ["landmarks_worst_per_method.png", "landmarks_mrf.png"]
    # best first, worst last; no truth, or no landmarks of its own (p4: the template's ids name other points): out
    assert out["poses"] == {"mrf": ["p1", "p2"]}
    assert all((tmp_path / f).stat().st_size > 1000 for f in out["figures"])
    (tmp_path / "own").mkdir()
    (tmp_path / "own" / "p4.txt").write_text("".join(f"{perm[v]},{n}\n" for v, n in ((0, "a"), (7, "b"), (3, "c"))))
    out = figures.landmark_figures(mesh, {"t": mesh, "p1": mesh, "p4": shuffled}, str(lm),
                                   mrf={k: preds[k] for k in ("p1", "p4")}, landmark_files=str(tmp_path / "own"),
                                   out_dir=str(tmp_path))
    assert out["poses"] == {"mrf": ["p1", "p4"]}                   # p4 drawn at its own landmarks
    # the captions are the tables' measure: the mean of corr.dense_measures' errors of the pose
    dense = figures.dense_figures(mesh, {"p1": mesh, "p2": mesh},
                                  mobius={"p1": {"vertex_map": np.arange(8)}, "p2": np.roll(np.arange(8), 1)},
                                  dense_measures={"p1": {"errors": {"mobius": np.zeros(5)}},
                                                  "p2": {"errors": {"mobius": np.array([0.1, 0.3])}}},
                                  out_dir=str(tmp_path))
    assert dense["figures"] == ["dense_mobius.png"] and dense["mean_error"]["mobius"] == {"p1": 0.0, "p2": 0.2}
    dense = figures.dense_figures(mesh, {"p1": mesh}, mobius={"p1": np.arange(8)}, out_dir=str(tmp_path))
    assert dense["mean_error"] == {"mobius": {}}                   # no true map: no number


def test_azimuth_figure(tmp_path):
    from shapecorr import figures
    gt = tmp_path / "gt.csv"
    gt.write_text("shape,azimuth_steps,azimuth_deg\na,0,0\nb,4,90\nc,8,180\nd,1,22.5\n")
    solution = {"names": ["a", "b", "c", "d"], "labels": np.array([3, 7, 11, 9]), "n_views": 16}
    out = figures.azimuth_figure(solution, str(gt), out_dir=str(tmp_path))
    assert out["figures"] == ["azimuth_recovered_vs_true.png"] and out["exact"] == 0.75   # d is off
    assert (tmp_path / "azimuth_recovered_vs_true.png").stat().st_size > 1000
    assert figures.azimuth_figure(solution, None, out_dir=str(tmp_path)) == {"figures": []}


def test_stand_up_turns_the_longest_axis_up():
    V = np.random.default_rng(1).normal(size=(50, 3)) * [5.0, 1.0, 2.0]     # long along x
    axis = pm.up_axis(V)
    U = pm.stand_up(V, axis)
    assert axis == 0 and pm.up_axis(U) == 1
    assert np.allclose(np.linalg.norm(U, axis=1), np.linalg.norm(V, axis=1))   # a rotation: lengths kept
    assert np.allclose(pm.stand_up(V * [1, 1, 1], 1), V)
    W = V[:, [1, 2, 0]]                                                         # long along z
    assert pm.up_axis(W) == 2 and pm.up_axis(pm.stand_up(W, 2)) == 1
    M = np.stack([pm.stand_up(np.eye(3), a) for a in (0, 2)])
    assert np.allclose([np.linalg.det(m) for m in M], 1.0)                      # proper rotations


def test_pull_back_colors_leaves_out_template_vertices_without_an_image():
    V = np.random.default_rng(1).normal(size=(20, 3))
    colors = pm.coordinate_colors(V)
    vm = np.arange(20)
    vm[5] = -1
    out = pm.pull_back_colors(colors, vm, V)
    keep = np.arange(20) != 5
    assert np.allclose(out[keep], colors[keep])
    assert np.allclose(out[5], colors[keep][np.argmin(np.linalg.norm(V[keep] - V[5], axis=1))])
    with pytest.raises(ValueError, match="at least one image"):
        pm.pull_back_colors(colors, np.full(20, -1), V)


def sphere_mesh(n_lat: int = 24, n_lon: int = 48):
    """A UV sphere of radius 1 (poles at +-y), outward triangles."""
    V = [[0.0, 1.0, 0.0]]
    for i in range(1, n_lat):
        t = np.pi * i / n_lat
        V += [[np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)]
              for p in np.linspace(0, 2 * np.pi, n_lon, endpoint=False)]
    V.append([0.0, -1.0, 0.0])
    ring = lambda i, j: 1 + (i - 1) * n_lon + j % n_lon  # noqa: E731
    F = [[0, ring(1, j), ring(1, j + 1)] for j in range(n_lon)]
    for i in range(1, n_lat - 1):
        for j in range(n_lon):
            F += [[ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)], [ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)]]
    F += [[len(V) - 1, ring(n_lat - 1, j + 1), ring(n_lat - 1, j)] for j in range(n_lon)]
    return np.array(V), np.array(F)


def test_landmark_figure_one_known_mistake(tmp_path):
    """A run with one known mistake (landmark 3 placed on landmark 6): exactly one red line per view, from where
    landmark 3 was put to where it is; labels >= 9 pt, none covering another (a cluster of 8 landmarks close
    together on the front), the views named, the legend written."""
    V, F = sphere_mesh()
    front = np.nonzero((V[:, 2] > 0.85))[0][:8]                 # 8 landmarks crowded around the front pole
    assert len(front) == 8
    pred = np.arange(8)
    pred[2] = 5
    out = tmp_path / "landmarks.png"
    drawn = pm.plot_landmark_panels((V, F), {"pose": (V, F)}, {"template": front, "pose": front}, {"pose": pred},
                                    [f"landmark_{i}" for i in range(8)], "one mistake", out, views=(0, 1))
    assert out.stat().st_size > 1000
    lines = drawn["wrong_lines"]
    assert [panel for panel, _ in lines] == ["pose, front view", "pose, view turned 45\N{DEGREE SIGN}"]
    for view, (_, (x0, y0, x1, y1)) in zip((0, 1), lines):
        Vn = pm.normalise_for_picture(pm.stand_up(V, pm.up_axis(V)))
        xy, _ = pm.project_vertices(Vn, F, front[[5, 2]], view=view, n_views=8, size=300)
        assert np.allclose([x0, y0], xy[0]) and np.allclose([x1, y1], xy[1])   # placed -> true
    labels = drawn["labels"]
    assert len(labels) == 4 * 8 and min(size for _, _, size, _ in labels) >= 9
    for panel in {p for p, *_ in labels}:
        boxes = [b for p, _, _, b in labels if p == panel]
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                a, b = boxes[i], boxes[j]
                overlap = min(a[2], b[2]) - max(a[0], b[0]), min(a[3], b[3]) - max(a[1], b[1])
                assert min(overlap) <= 0.5, f"{panel}: labels {i + 1} and {j + 1} overlap"
    # labels moved away from their crowded points are joined to them: each leader points back at its label's
    # centre and leaves from the edge of that label's text box (2 pt of air), ending outside every label
    leaders = drawn["leaders"]
    assert leaders
    air = pm.LEADER_GAP_PT * pm.LANDMARK_DPI / 72
    for panel, (x0, y0, x1, y1) in leaders:
        boxes = [np.asarray(b) for p, _, _, b in labels if p == panel]
        start, along = np.array([x0, y0]), np.array([x1 - x0, y1 - y0]) / np.hypot(x1 - x0, y1 - y0)
        centres = [((b[0] + b[2]) / 2, (b[1] + b[3]) / 2) for b in boxes]
        behind = [(np.dot(start - c, along), b) for c, b in zip(centres, boxes)
                  if abs(along[0] * (c[1] - start[1]) - along[1] * (c[0] - start[0])) < 1.0 and np.dot(start - c, along) >= 0]
        assert behind, (panel, (x0, y0))
        _, own = min(behind, key=lambda db: db[0])             # the label the leader comes from
        half = (own[2:] - own[:2]) / 2 + air
        gap = np.abs(start - (own[:2] + own[2:]) / 2) - half  # on the box's edge: 0 along one axis, <= 0 the other
        assert abs(max(gap)) < 1.0, (panel, (x0, y0), own)
        assert not any(b[0] < x1 < b[2] and b[1] < y1 < b[3] for b in boxes), (panel, (x1, y1))


def test_leader_line_runs_from_the_label_box_edge_to_just_short_of_the_point():
    assert np.allclose(pm.leader_line([0, 0], [10, 0], [2, 1], 1.0), [[2, 0], [9, 0]])
    assert np.allclose(pm.leader_line([0, 0], [10, 5], [2, 1], 0.0), [[2, 1], [10, 5]])   # leaves by the top
    assert np.allclose(pm.leader_line([0, 0], [0, -4], [2, 1], 1.0), [[0, -1], [0, -3]])
    assert pm.leader_line([0, 0], [1.5, 0], [2, 1], 0.5) is None      # the point is inside the box
    assert pm.leader_line([0, 0], [2.4, 0], [2, 1], 0.5) is None      # ... or within the shrink of its edge


@pytest.mark.parametrize("width", [2.5, 4.0, 9.0])
def test_long_titles_are_wrapped_inside_the_figure(width):
    """A one-pose dense figure is narrow: its long title is wrapped, not cut at the figure's edges."""
    from corr_core.plotting.charts import pyplot

    plt = pyplot()
    fig = plt.figure(figsize=(width, 3))
    title = ("dense_auto: template coordinates as RGB, pulled back through the dense map (best .. worst pose)"
             "\ngreen: right; red x: wrong, a red line to the true landmark (blue ring); faint: hidden from this side")
    text = fig.suptitle(pm.fit_title(title, width, 10), fontsize=10)
    fig.canvas.draw()
    box, page = text.get_window_extent(), fig.bbox
    plt.close(fig)
    assert box.x0 >= page.x0 and box.x1 <= page.x1


def test_landmark_figures_of_the_same_meshes_share_their_scenes_and_pictures(tmp_path, monkeypatch):
    """plot_landmark_methods draws the template and the same poses in several figures: each mesh's ray-casting
    scene and grey picture per camera are made once, and the files are the same as drawn without sharing."""
    V, F = sphere_mesh()
    front = np.nonzero((V[:, 2] > 0.85))[0][:8]
    pose = (V * np.array([1.0, 1.1, 0.9]), F)
    pred = np.arange(8)
    pred[2] = 5
    methods = {"a": {"pose": pred}, "b": {"pose": np.arange(8)}}
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    for method, preds in methods.items():                       # each figure on its own, nothing shared
        pm.plot_landmark_panels((V, F), {"pose": pose}, {"template": front, "pose": front}, preds,
                                [f"l{i}" for i in range(8)], f"{method}: x", fresh / f"{method}.png", views=(0, 1))
    built, scene = [], pm._scene
    monkeypatch.setattr(pm, "_scene", lambda V, F: built.append(len(V)) or scene(V, F))
    shared, pictures = tmp_path / "shared", {}
    shared.mkdir()
    for method, preds in methods.items():
        pm.plot_landmark_panels((V, F), {"pose": pose}, {"template": front, "pose": front}, preds,
                                [f"l{i}" for i in range(8)], f"{method}: x", shared / f"{method}.png", views=(0, 1),
                                pictures=pictures)
    assert len(built) == 2                                       # the template's scene and the pose's, once each
    for method in methods:
        assert (fresh / f"{method}.png").read_bytes() == (shared / f"{method}.png").read_bytes()
