"""Pictures of meshes with per-vertex colours and labelled points, rendered with the project's own CPU ray
caster (Open3D ``RaycastingScene``, the cameras of ``corr_core.alignment.render``): no display needed.

Conventions: meshes are V: (n,3) float, F: (m,3) int; for the picture only, every mesh of a figure is turned
so that the template's longest bounding-box axis is up (y) and normalised (bounding-box centre at the origin,
largest distance 1). Views are the cameras of
``render.camera_frames(n_views)``: view k looks from azimuth k * 360 / n_views degrees (view 0 from +z).
Images are (S, S, 3) float RGB in [0, 1], white background.
"""
from __future__ import annotations

import functools
import os

import numpy as np

from corr_core.open3d_loader import load_open3d
from corr_core.alignment.render import camera_frames, view_rays
from corr_core.geometry.primitives import face_normals
from corr_core.plotting.charts import pyplot, save_figure

__all__ = ["up_axis", "stand_up", "normalise_for_picture", "render_colored", "project_vertices", "coordinate_colors",
           "pull_back_colors", "crop_box", "plot_landmark_panels", "plot_dense_panels", "plot_azimuths",
           "spread_best_to_worst", "plot_landmark_methods", "plot_dense_methods"]

MARGIN = 1.05


def normalise_for_picture(V: np.ndarray) -> np.ndarray:
    """V: (n,3) -> (n,3) float64 with its bounding-box centre at the origin and max distance 1."""
    V = np.asarray(V, np.float64)
    centred = V - (V.min(0) + V.max(0)) / 2
    radius = float(np.linalg.norm(centred, axis=1).max()) or 1.0
    return centred / radius


def up_axis(V: np.ndarray) -> int:
    """The axis (0 x, 1 y, 2 z) of the largest bounding-box extent of V: (n,3), shown upright (e.g. a body
    lying along x, as in SCAPE, stands up in the pictures)."""
    V = np.asarray(V, np.float64)
    return int(np.argmax(V.max(0) - V.min(0)))


def stand_up(V: np.ndarray, axis: int) -> np.ndarray:
    """V: (n,3) rotated (a proper rotation) so that ``axis`` points along +y, the cameras' up."""
    V = np.asarray(V, np.float64)
    x, y, z = V[:, 0], V[:, 1], V[:, 2]
    if axis == 0:
        return np.stack([-y, x, z], axis=1)    # Rz(+90 deg): +x -> +y
    if axis == 2:
        return np.stack([x, z, -y], axis=1)    # Rx(-90 deg): +z -> +y
    return V


def _scene(V: np.ndarray, F: np.ndarray):
    o3d = load_open3d()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(V, np.float32)), o3d.core.Tensor(np.asarray(F, np.uint32)))
    return scene


@functools.lru_cache(maxsize=16)
def _rays(view: int, n_views: int, size: int, elevation_deg: float):
    """The Open3D tensor of camera ``view``'s rays (size, size, 6): the same for every mesh (all are normalised
    to the same box), so made once per camera."""
    rays = view_rays(n_views=n_views, image_size=size, elevation_deg=elevation_deg, margin=MARGIN, views=(view,))
    return load_open3d().core.Tensor(np.ascontiguousarray(rays[0]))


def render_colored(V: np.ndarray, F: np.ndarray, colors: np.ndarray, *, view: int = 0, n_views: int = 8,
                   size: int = 320, elevation_deg: float = 10.0, ambient: float = 0.35, scene=None) -> np.ndarray:
    """Render a normalised mesh with per-vertex colours (interpolated over each triangle), headlight shading.

    Args:
        V: (n,3) normalised vertices (see :func:`normalise_for_picture`); F: (m,3) int.
        colors: (n,3) float RGB in [0,1] per vertex.
        view, n_views, elevation_deg: the camera (view k of ``camera_frames(n_views, elevation_deg)``).
        size: pixels per side; ambient: shade = ambient + (1 - ambient) * |n . d|.
        scene: the mesh's ray-casting scene when already built (``_scene(V, F)``; reused for several pictures).
    Returns:
        (size, size, 3) float32 RGB in [0, 1], white background.
    """
    V, F, colors = np.asarray(V, np.float64), np.asarray(F, np.int64), np.asarray(colors, np.float64)
    if colors.shape != (len(V), 3):
        raise ValueError(f"colors must be (n_vertices, 3) = ({len(V)}, 3), got {colors.shape}")
    hit = (scene or _scene(V, F)).cast_rays(_rays(view, n_views, size, elevation_deg))
    face = hit["primitive_ids"].numpy().astype(np.int64)
    uv = hit["primitive_uvs"].numpy()
    valid = np.isfinite(hit["t_hit"].numpy())
    image = np.ones((size, size, 3), np.float32)
    f, u, v = face[valid], uv[valid, 0], uv[valid, 1]
    tri = F[f]
    rgb = (1 - u - v)[:, None] * colors[tri[:, 0]] + u[:, None] * colors[tri[:, 1]] + v[:, None] * colors[tri[:, 2]]
    back = camera_frames(n_views=n_views, elevation_deg=elevation_deg)[view, 2]
    shade = ambient + (1 - ambient) * np.abs(face_normals(V, F)[f] @ back)
    image[valid] = np.clip(rgb * shade[:, None], 0, 1)
    return image


def project_vertices(V: np.ndarray, F: np.ndarray, vids: np.ndarray, *, view: int = 0, n_views: int = 8,
                     size: int = 320, elevation_deg: float = 10.0, scene=None) -> tuple[np.ndarray, np.ndarray]:
    """Pixel positions of vertices ``vids`` (k,) in the picture of :func:`render_colored`, and whether each is
    visible (not hidden by the surface). ``scene``: as :func:`render_colored`'s.

    Returns (xy (k,2) float pixel column/row, visible (k,) bool)."""
    V = np.asarray(V, np.float64)
    right, up, back = camera_frames(n_views=n_views, elevation_deg=elevation_deg)[view]
    P = V[np.asarray(vids, np.int64)]
    half = size / 2
    xy = np.stack([(P @ right / MARGIN + 1) * half, (1 - P @ up / MARGIN) * half], axis=1)
    o3d = load_open3d()
    origins = P + 3.0 * back
    rays = np.concatenate([origins, np.broadcast_to(-back, origins.shape)], axis=1).astype(np.float32)
    t_hit = (scene or _scene(V, F)).cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    return xy, t_hit >= 3.0 - 0.02


def coordinate_colors(V: np.ndarray) -> np.ndarray:
    """A smooth function on a mesh as colours: the normalised coordinates (x, y, z) as (R, G, B), (n,3) in [0,1]."""
    V = np.asarray(V, np.float64)
    lo, hi = V.min(0), V.max(0)
    return (V - lo) / np.where(hi > lo, hi - lo, 1.0)


def pull_back_colors(template_colors: np.ndarray, vertex_map: np.ndarray, target_V: np.ndarray) -> np.ndarray:
    """Colours of the target vertices through a dense map template vertex i -> target vertex ``vertex_map[i]``.

    template_colors: (n_s,3); vertex_map: (n_s,) int target vertex ids, -1 for a template vertex with no image
    (left out); target_V: (n_t,3). A target vertex some template vertices map to gets their mean colour; the
    others take the colour of the nearest such vertex (in 3D). Returns (n_t,3) float.
    """
    from scipy.spatial import cKDTree

    vertex_map = np.asarray(vertex_map, np.int64)
    n_t = len(target_V)
    if vertex_map.shape != (len(template_colors),) or vertex_map.max() < 0 or vertex_map.min() < -1 \
            or vertex_map.max() >= n_t:
        raise ValueError(f"vertex_map must be ({len(template_colors)},) ids in [0, {n_t}) or -1, with at least "
                         f"one image; got shape {vertex_map.shape}")
    has = vertex_map >= 0
    template_colors, vertex_map = np.asarray(template_colors)[has], vertex_map[has]
    sums = np.zeros((n_t, 3))
    np.add.at(sums, vertex_map, template_colors)
    counts = np.bincount(vertex_map, minlength=n_t)
    hit = np.nonzero(counts)[0]
    out = np.empty((n_t, 3))
    out[hit] = sums[hit] / counts[hit, None]
    miss = np.nonzero(counts == 0)[0]
    if len(miss):
        out[miss] = out[hit[cKDTree(target_V[hit]).query(target_V[miss])[1]]]
    return out


GREY = np.array([0.78, 0.78, 0.80])


def crop_box(images: list[np.ndarray], *, pad: int = 6) -> tuple[slice, slice]:
    """(rows, columns) slices of the smallest box holding every non-white pixel of the (S,S,3) images, padded."""
    ink = np.zeros(images[0].shape[:2], bool)
    for im in images:
        ink |= (im < 0.999).any(axis=2)
    if not ink.any():
        return slice(None), slice(None)
    rows, cols = np.nonzero(ink.any(1))[0], np.nonzero(ink.any(0))[0]
    S0, S1 = ink.shape
    return (slice(max(rows[0] - pad, 0), min(rows[-1] + pad + 1, S0)),
            slice(max(cols[0] - pad, 0), min(cols[-1] + pad + 1, S1)))


def _show(ax, image: np.ndarray, box: tuple[slice, slice]) -> None:
    """Show the ``box`` part of an image with pixel coordinates kept (so projected points still line up)."""
    r, c = box
    r0, c0 = r.start or 0, c.start or 0
    sub = image[r, c]
    ax.imshow(sub, extent=(c0 - 0.5, c0 + sub.shape[1] - 0.5, r0 + sub.shape[0] - 0.5, r0 - 0.5))
    ax.set_xticks([])
    ax.set_yticks([])
    for s in ax.spines.values():
        s.set_visible(False)


LABEL_PT = 9.0                     # landmark numbers and legend, in points
RIGHT, WRONG, TRUE_EDGE = "#22aa33", "#dd2222", "#1f5fbf"


def fit_title(text: str, width_in: float, fontsize: float) -> str:
    """``text`` wrapped onto lines that fit a figure ``width_in`` inches wide at ``fontsize`` points (about 0.62 em
    per character), each existing line on its own, so a long title is never cut at the figure's edges."""
    import textwrap

    chars = max(20, int(width_in * 72 / (0.62 * fontsize)))
    return "\n".join(part for line in text.split("\n") for part in textwrap.wrap(line, chars) or [""])


def view_name(view: int, *, n_views: int = 8) -> str:
    """How a figure names camera ``view`` of ``n_views`` (azimuth view * 360 / n_views degrees; 0: the front)."""
    az = view * 360.0 / n_views
    return "front view" if view == 0 else f"view turned {az:g}\N{DEGREE SIGN}"


def place_labels(points: np.ndarray, sizes: np.ndarray, bounds: tuple[float, float, float, float],
                 dot: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Where to put one text label per point so that labels cover neither each other nor the points (greedy, in
    the order given; all in display pixels, y up).

    Args:
        points: (k,2) anchor positions; sizes: (k,2) label width and height; bounds: (x0, y0, x1, y1) the area
            labels should stay in; dot: the radius kept free around every point; step: the distance between
            candidate rings around a point.
    Returns (centres (k,2) of the labels, leader (k,) bool: the label sits away from its point, so a line
        should join them).
    """
    points, sizes = np.asarray(points, float), np.asarray(sizes, float)
    dirs = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1], [1, 0], [-1, 0], [0, 1], [0, -1],
                     [2, 1], [-2, 1], [2, -1], [-2, -1]], float)
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    placed = np.zeros((0, 4))        # (x0, y0, x1, y1) of the labels placed so far
    centres, leader = np.zeros_like(points), np.zeros(len(points), bool)
    ax_, ay_ = np.abs(dirs[:, 0]), np.abs(dirs[:, 1])

    def costs(boxes: np.ndarray) -> np.ndarray:
        """(m,) cost of each candidate box (m,4): overlap with the labels placed, points covered, outside."""
        x0, y0, x1, y1 = boxes.T
        overlap = 10.0 * np.maximum(0.0, np.minimum(x1[:, None], placed[:, 2]) - np.maximum(x0[:, None], placed[:, 0])) \
            * np.maximum(0.0, np.minimum(y1[:, None], placed[:, 3]) - np.maximum(y0[:, None], placed[:, 1]))
        # summed in placing order (cumsum runs left to right): the same sums as box by box
        c = np.cumsum(overlap, axis=1)[:, -1] if len(placed) else np.zeros(len(boxes))
        px, py = points[:, 0][None, :], points[:, 1][None, :]
        near = ((px > (x0 - dot)[:, None]) & (px < (x1 + dot)[:, None]) & (py > (y0 - dot)[:, None])
                & (py < (y1 + dot)[:, None])).sum(axis=1)
        c += 0.5 * dot * dot * near
        out = (np.maximum(0.0, bounds[0] - x0) + np.maximum(0.0, x1 - bounds[2]) + np.maximum(0.0, bounds[1] - y0)
               + np.maximum(0.0, y1 - bounds[3]))
        return c + 50.0 * out * (y1 - y0)

    for i, (p, (w, h)) in enumerate(zip(points, sizes)):
        best = None
        for ring in range(10):
            # each box's edge (not its centre) at distance dot + ring * step from the point, along each direction
            reach = dot + ring * step + 0.5 * ax_ * w + 0.5 * ay_ * h
            c = p + dirs * reach[:, None]
            boxes = np.stack([c[:, 0] - w / 2, c[:, 1] - h / 2, c[:, 0] + w / 2, c[:, 1] + h / 2], axis=1)
            score = costs(boxes) + 1e-3 * ring
            k = int(np.argmin(score))        # the first of equals, as the directions are tried in order
            if best is None or score[k] < best[0]:
                best = (score[k], c[k], boxes[k], ring)
            if best[0] < 1e-2:
                break
        _, centres[i], box, ring = best
        leader[i] = ring > 0
        placed = np.vstack([placed, box])
    return centres, leader


def _label_points(fig, ax, xy: np.ndarray, texts: list[str], colours: list[str], alphas: np.ndarray,
                  others: np.ndarray, label_sizes: dict | None = None) -> None:
    """Label the points ``xy`` (k,2, data = image pixels) of an axes with ``texts`` at ``LABEL_PT``, placed by
    :func:`place_labels` (away from each other and from ``others`` (n,2), the other marks in the picture) with a
    thin leader line when a label had to move away from its point. ``label_sizes``: {text: (w, h) pixels}
    measured so far in this figure (the same numbers label every panel), filled in here."""
    if not len(xy):
        return
    renderer = fig.canvas.get_renderer()
    to_px = ax.transData.transform
    label_sizes = {} if label_sizes is None else label_sizes
    for t in texts:
        if t not in label_sizes:
            probe = ax.text(0, 0, t, fontsize=LABEL_PT, fontweight="bold")
            bb = probe.get_window_extent(renderer)
            label_sizes[t] = (bb.width + 3, bb.height + 3)   # a little air around each label
            probe.remove()
    sizes = [label_sizes[t] for t in texts]
    pts = to_px(np.asarray(xy, float))
    box = ax.get_window_extent(renderer)
    px_per_pt = fig.dpi / 72.0
    everything = np.concatenate([pts, to_px(np.asarray(others, float).reshape(-1, 2))]) if len(others) else pts
    centres, leader = place_labels(everything, np.array(sizes + [(0.0, 0.0)] * (len(everything) - len(pts))),
                                   (box.x0, box.y0, box.x1, box.y1), dot=4.5 * px_per_pt, step=5 * px_per_pt)
    from matplotlib.lines import Line2D

    to_data = ax.transData.inverted().transform
    for i, t in enumerate(texts):
        offset = (centres[i] - pts[i]) / px_per_pt
        ax.annotate(t, xy[i], xytext=tuple(offset), textcoords="offset points", ha="center", va="center",
                    fontsize=LABEL_PT, fontweight="bold", color=colours[i], alpha=alphas[i], gid="landmark-label",
                    annotation_clip=False)
        text_half = (np.asarray(label_sizes[t]) - 3) / 2 + LEADER_GAP_PT * px_per_pt
        ends = leader_line(centres[i], pts[i], text_half, LEADER_SHRINK_PT * px_per_pt) if leader[i] else None
        if ends is not None:
            (x0, y0), (x1, y1) = to_data(ends)
            ax.add_artist(Line2D([x0, x1], [y0, y1], lw=0.7, color="#444", alpha=alphas[i], solid_capstyle="butt",
                                 zorder=3, clip_on=False, gid="leader"))


LEADER_GAP_PT = 2.0      # a leader line stops this far from its label's text (as matplotlib's annotation arrows)
LEADER_SHRINK_PT = 2.0   # ... and this far short of its point


def leader_line(centre: np.ndarray, point: np.ndarray, half_size: np.ndarray, shrink: float) -> np.ndarray | None:
    """The segment joining a label to its point, in display pixels: from where the line from the label's centre
    to the point leaves the label's box to ``shrink`` short of the point; None when the point is that close to
    the box (nothing to draw).

    Args: centre: (2,) the label's centre; point: (2,); half_size: (2,) half the width and height of the box;
        shrink: pixels. Returns (2,2) [start, end] or None.
    """
    centre, point = np.asarray(centre, float), np.asarray(point, float)
    direction = point - centre
    length = float(np.hypot(*direction))
    if length == 0.0:
        return None
    with np.errstate(divide="ignore"):
        leave = float(np.min(np.where(direction != 0, np.asarray(half_size, float) / np.abs(direction), np.inf)))
    start, end = centre + min(leave, 1.0) * direction, point - shrink / length * direction
    if np.dot(end - start, direction) <= 0:
        return None
    return np.stack([start, end])


def plot_landmark_panels(template: tuple, poses: dict, landmark_vids: dict, predictions: dict,
                         names: list[str], title: str, path, views: tuple[int, ...] = (0, 1), *, n_views: int = 8,
                         size: int = 300, wrap: int | None = None, legend: bool = True,
                         pictures: dict | None = None) -> dict:
    """The template and some test poses side by side with the landmarks as numbered dots.

    Args:
        template: (V, F) of the template; poses: {pose name: (V, F)} in display order (e.g. best .. worst).
        landmark_vids: {"template": (L,) vertex ids, pose name: (L,) vertex ids} (the landmark files).
        predictions: {pose name: (L,) predicted landmark index per template landmark}; truth i -> i, so
            ``pred[i] != i`` is drawn as a red dot with a cross, joined by a red line to the true landmark i
            (a blue ring); green dot: right.
        names: (L,) landmark names (numbered in the legend); title: the figure title.
        views: the cameras shown (rows, each named on the left).
        wrap: with one view, at most this many panels per row (the panels wrap onto more rows).
        legend: list the numbered landmark names next to the panels.
        pictures: a dict kept by the caller across figures of the same meshes: each mesh's ray-casting scene and
            grey picture per camera are made once (keyed by the arrays' identity, so only while they live).
    Writes one PNG to ``path``. Numbers are ``LABEL_PT`` points, moved apart (with a leader line) where they
    would overlap. Returns what was drawn (:func:`_drawn`: the lines from wrong placements, the labels), for checks.
    """
    plt = pyplot()
    axis = up_axis(template[0])
    panels = []   # (name, row, view, image, xy, visible, right, xy_true, visible_true)
    pictures = {} if pictures is None else pictures
    for name, (V, F) in [("template", template)] + list(poses.items()):
        if (id(V), id(F)) not in pictures:
            Vn = normalise_for_picture(stand_up(V, axis))
            pictures[(id(V), id(F))] = {"V": Vn, "scene": _scene(Vn, F), "keep": (V, F)}
        mesh = pictures[(id(V), id(F))]
        Vn, scene = mesh["V"], mesh["scene"]
        L = len(landmark_vids[name])
        pred = np.arange(L) if name == "template" else np.asarray(predictions[name], np.int64)
        own = np.asarray(landmark_vids[name], np.int64)
        for r, view in enumerate(views):
            if (view, n_views, size) not in mesh:
                mesh[(view, n_views, size)] = render_colored(Vn, F, np.tile(GREY, (len(Vn), 1)), view=view,
                                                             n_views=n_views, size=size, scene=scene)
            xy, visible = project_vertices(Vn, F, np.concatenate([own[pred], own]), view=view, n_views=n_views,
                                           size=size, scene=scene)
            panels.append((name, r, view, mesh[(view, n_views, size)], xy[:L], visible[:L], pred == np.arange(L),
                           xy[L:], visible[L:]))
    box = crop_box([p[3] for p in panels])
    n_panels = len(poses) + 1
    n_cols = min(wrap, n_panels) if wrap and len(views) == 1 else n_panels
    n_rows = len(views) if n_cols == n_panels else -(-n_panels // n_cols)
    place = (lambda k, r: (r, k // len(views))) if n_cols == n_panels else (lambda k, r: divmod(k, n_cols))
    aspect = (box[1].stop - box[1].start) / (box[0].stop - box[0].start) if box[0].start is not None else 1.0
    aspect = max(aspect, 0.8)   # room for the titles
    panel_w, panel_h = 3.0 * aspect, 3.2
    legend_w = (0.35 + 0.075 * LABEL_PT / 9 * max((len(n) for n in names), default=4)) if legend else 0.0
    widths = [panel_w] * n_cols + ([legend_w] if legend else [])
    cameras = "" if n_cols == n_panels else f" ({view_name(views[0], n_views=n_views)})"
    suptitle = fit_title(title + cameras + "\ngreen: right; red x: wrong, a red line to the true landmark (blue "
                         "ring); faint: hidden from this side", sum(widths) + 0.4, 10)
    top_in = 0.55 + 0.2 * (suptitle.count("\n") + 1)    # the title's lines, then the panels' two-line titles
    fig = plt.figure(figsize=(sum(widths) + 0.4, panel_h * n_rows + top_in))
    grid = fig.add_gridspec(n_rows, len(widths), width_ratios=widths, wspace=0.04,
                            hspace=0.12 if n_cols == n_panels else 0.18,
                            left=0.4 / (sum(widths) + 0.4), right=0.995, bottom=0.01,
                            top=1 - top_in / (panel_h * n_rows + top_in))
    axes = np.array([[fig.add_subplot(grid[i, j]) for j in range(n_cols)] for i in range(n_rows)])
    for ax in axes.ravel():
        ax.axis("off")
    labelled = []
    title_of = lambda k: f"{panels[k][0]}, {view_name(panels[k][2], n_views=n_views)}"  # noqa: E731
    for k, (name, r, view, image, xy, visible, right, xy_true, visible_true) in enumerate(panels):
        ax = axes[place(k, r)]
        ax.axis("on")
        _show(ax, image, box)
        alpha = np.where(visible, 1.0, 0.45)
        alpha_true = np.where(visible | visible_true, 1.0, 0.45)
        for i in np.nonzero(~right)[0]:     # each wrong placement: a line to where the landmark really is
            ax.plot([xy[i, 0], xy_true[i, 0]], [xy[i, 1], xy_true[i, 1]], "-", color=WRONG, lw=1.3,
                    alpha=alpha_true[i], gid="wrong-to-true", zorder=3)
        # the markers as one line per style (a line per marker made most of the figure's time)
        for a in (1.0, 0.45):
            ring = ~right & (alpha_true == a)
            if ring.any():
                ax.plot(xy_true[ring, 0], xy_true[ring, 1], "o", ms=6, mfc="none", mec=TRUE_EDGE, mew=1.4, alpha=a,
                        gid="true-landmark", zorder=4)
            for ok in (True, False):
                dots = (right == ok) & (alpha == a)
                if dots.any():
                    ax.plot(xy[dots, 0], xy[dots, 1], "o", ms=5.5, mfc=RIGHT if ok else WRONG, mec="k", mew=0.5,
                            alpha=a, zorder=5)
        for a in (1.0, 0.45):
            crosses = ~right & (alpha == a)
            if crosses.any():
                ax.plot(xy[crosses, 0], xy[crosses, 1], "x", ms=9, color=WRONG, mew=1.4, alpha=a, zorder=5)
        if r == 0 or n_cols != n_panels:
            wrong = int((~right).sum())
            ax.set_title(name if name == "template" else f"{name}\n{len(right) - wrong}/{len(right)} right",
                         fontsize=9, color="k" if wrong == 0 else "#aa0000")
        if place(k, r)[1] == 0 and n_cols == n_panels:
            ax.set_ylabel(view_name(view, n_views=n_views), fontsize=9)
        labelled.append((ax, xy, right, alpha, xy_true[~right]))
    for ax in axes.ravel():
        ax.apply_aspect()     # the axes take their final (equal-aspect) boxes: labels are placed in final pixels
    label_sizes: dict = {}
    for ax, xy, right, alpha, others in labelled:
        _label_points(fig, ax, xy, [str(i + 1) for i in range(len(right))],
                      ["#111" if ok else "#aa0000" for ok in right], alpha, others, label_sizes)
    if legend:
        lax = fig.add_subplot(grid[:, -1])
        lax.axis("off")
        lax.text(0.02, 0.5, "\n".join(f"{i + 1:>2} {n}" for i, n in enumerate(names)), fontsize=LABEL_PT,
                 va="center", ha="left", family="monospace", transform=lax.transAxes)
    fig.suptitle(suptitle, fontsize=10)
    save_figure(fig, path, LANDMARK_DPI, tight_rect=None, close=False)
    drawn = _drawn(fig, [(ax, title_of(k)) for k, ax in enumerate(a for a, *_ in labelled)], LANDMARK_DPI)
    plt.close(fig)
    return drawn


LANDMARK_DPI = 90


def _drawn(fig, axes: list, dpi: float) -> dict:
    """What a landmark figure saved at ``dpi`` shows, read back from its artists: {"wrong_lines": [(panel, (x0, y0,
    x1, y1)) in image pixels], "labels": [(panel, text, font size pt, (x0, y0, x1, y1) saved pixels from the
    bottom left)], "leaders": [(panel, (x0, y0, x1, y1) saved pixels: label end, point end)]}."""
    from matplotlib.text import Text

    renderer = fig.canvas.get_renderer()
    out = {"wrong_lines": [], "labels": [], "leaders": []}
    for ax, panel in axes:
        for line in ax.lines:
            if line.get_gid() == "wrong-to-true":
                (x0, x1), (y0, y1) = line.get_xdata(), line.get_ydata()
                out["wrong_lines"].append((panel, (float(x0), float(y0), float(x1), float(y1))))
            elif line.get_gid() == "leader":
                (x0, y0), (x1, y1) = ax.transData.transform(np.column_stack(line.get_data())) * (dpi / fig.dpi)
                out["leaders"].append((panel, (float(x0), float(y0), float(x1), float(y1))))
        for t in ax.texts:
            if t.get_gid() == "landmark-label":
                bb = Text.get_window_extent(t, renderer)     # the text's own box (not its leader line)
                out["labels"].append((panel, t.get_text(), float(t.get_fontsize()), (bb.x0, bb.y0, bb.x1, bb.y1)))
    return out


def plot_dense_panels(template: tuple, poses: dict, vertex_maps: dict, captions: dict, title: str, path,
                      views: tuple[int, ...] = (0, 1), *, n_views: int = 8, size: int = 300) -> None:
    """The template coloured by its coordinates as RGB, and each pose coloured by that function pulled back
    through a dense map (same colour = corresponding point; a right map gives the template's pattern).

    Args:
        template: (V, F); poses: {pose name: (V, F)} in display order.
        vertex_maps: {pose name: (n_template,) target vertex of each template vertex}.
        captions: {pose name: text under the pose's title} (e.g. its mean error).
    Writes one PNG to ``path``.
    """
    plt = pyplot()
    Vt, Ft = template
    colors = coordinate_colors(normalise_for_picture(Vt))
    columns = [("template", Vt, Ft, colors)] + [(n, V, F, pull_back_colors(colors, vertex_maps[n], V))
                                                for n, (V, F) in poses.items()]
    axis = up_axis(Vt)
    panels = [(name, r, render_colored(normalise_for_picture(stand_up(V, axis)), F, col, view=view, n_views=n_views,
                                       size=size))
              for name, V, F, col in columns for r, view in enumerate(views)]
    box = crop_box([p[2] for p in panels])
    aspect = (box[1].stop - box[1].start) / (box[0].stop - box[0].start) if box[0].start is not None else 1.0
    aspect = max(aspect, 0.8)   # room for the titles
    width = 2.7 * aspect * len(columns) + 0.6
    suptitle = fit_title(title, width, 10)
    top = 0.25 + 0.2 * (suptitle.count("\n") + 1)      # inches above the panels for the title
    fig, axes = plt.subplots(len(views), len(columns), figsize=(width, 2.9 * len(views) + top), squeeze=False)
    for k, (name, r, image) in enumerate(panels):
        ax = axes[r, k // len(views)]
        _show(ax, image, box)
        if r == 0:
            ax.set_title(name + (f"\n{captions[name]}" if name in captions else ""), fontsize=9)
        if k < len(views):
            ax.set_ylabel(view_name(views[r], n_views=n_views), fontsize=9)
    fig.suptitle(suptitle, fontsize=10)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    save_figure(fig, path, 90, tight_rect=(0, 0, 1, 1 - top / fig.get_figheight()))


def plot_azimuths(true_deg: np.ndarray, recovered_deg: np.ndarray, names: list[str], step_deg: float,
                  path) -> None:
    """Recovered (after the best global offset) against true azimuth, degrees, one dot per shape (n,);
    shapes off the diagonal by more than half a view step are red and named."""
    plt = pyplot()
    true_deg, recovered_deg = np.asarray(true_deg, float), np.asarray(recovered_deg, float)
    diff = (recovered_deg - true_deg + 180.0) % 360.0 - 180.0
    wrong = np.abs(diff) > step_deg / 2
    fig, ax = plt.subplots(figsize=(4.6, 4.2))
    ax.plot([0, 360], [0, 360], color="#999", lw=1, zorder=0)
    ax.scatter(true_deg[~wrong], recovered_deg[~wrong], s=22, color="#22aa33", label="exact", zorder=2)
    ax.scatter(true_deg[wrong], recovered_deg[wrong], s=30, color="#dd2222", marker="x", label="off", zorder=3)
    for x, y, n in zip(true_deg[wrong], recovered_deg[wrong], np.asarray(names)[wrong]):
        ax.annotate(n, (x, y), xytext=(3, 3), textcoords="offset points", fontsize=7, color="#aa0000")
    ax.set_xlim(-10, 370)
    ax.set_ylim(-10, 370)
    ax.set_xticks(range(0, 361, 90))
    ax.set_yticks(range(0, 361, 90))
    ax.set_xlabel("true azimuth (deg)")
    ax.set_ylabel("recovered azimuth (deg, best global offset)")
    ax.set_title(f"recovered vs true azimuth: {int((~wrong).sum())}/{len(wrong)} exact", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    save_figure(fig, path, 100)


# ------------------------------------------------------------------------------------ per-method figure sets
def spread_best_to_worst(names_by_score: list[str], *, k: int = 4) -> list[str]:
    """Up to ``k`` names from a best-to-worst list, evenly spaced: always the first (best) and the last (worst)."""
    if len(names_by_score) <= k:
        return list(names_by_score)
    idx = np.unique(np.round(np.linspace(0, len(names_by_score) - 1, k)).astype(int))
    return [names_by_score[i] for i in idx]


def plot_landmark_methods(template: tuple, meshes: dict, landmark_vids, names: list[str],
                          methods: dict, out_dir: str, views: tuple[int, ...] = (0, 1), *, max_poses: int = 4,
                          worst_file: str = "landmarks_worst_per_method.png") -> tuple[list[str], dict]:
    """Per landmark method, the template and up to ``max_poses`` test poses (best .. worst by accuracy) with the
    predicted landmarks as numbered dots (``landmarks_<method>.png``), and one picture of every method's worst pose
    (``worst_file``, first camera only). The truth is landmark i -> landmark i.

    Args:
        template: (V, F); meshes: {pose: (V, F)}; names: (L,) landmark names.
        landmark_vids: {"template": (L,) int, pose: (L,) int} each mesh's landmark vertices, or one (L,) int
            array when every mesh has the template's vertex numbering.
        methods: {method: {pose: (L,) predicted landmark index}} (poses with a truth only).
    Returns (file names written, {method: [poses shown, best first]}).
    """
    if not isinstance(landmark_vids, dict):
        landmark_vids = {"template": landmark_vids, **{m: landmark_vids for p in methods.values() for m in p}}
    figures, shown, pictures = [], {}, {}
    for method, preds in methods.items():
        accuracy = {m: float(np.mean(p == np.arange(len(p)))) for m, p in preds.items()}
        poses = spread_best_to_worst(sorted(preds, key=lambda m: (-accuracy[m], m)), k=max_poses)
        file = f"landmarks_{method}.png"
        mean = float(np.mean(list(accuracy.values())))
        plot_landmark_panels(template, {m: meshes[m] for m in poses},
                             {"template": landmark_vids["template"], **{m: landmark_vids[m] for m in poses}},
                             {m: preds[m] for m in poses}, list(names),
                             f"{method}: landmarks on the best .. worst test poses (mean accuracy {mean:.2f})",
                             os.path.join(out_dir, file), views=views, pictures=pictures)
        figures.append(file)
        shown[method] = poses
    if shown:
        worst = {f"{method}: {poses[-1]}": (method, poses[-1]) for method, poses in shown.items()}
        plot_landmark_panels(template, {k: meshes[pose] for k, (_, pose) in worst.items()},
                             {"template": landmark_vids["template"],
                              **{k: landmark_vids[pose] for k, (_, pose) in worst.items()}},
                             {k: methods[m][pose] for k, (m, pose) in worst.items()}, list(names),
                             "the worst test pose of each method", os.path.join(out_dir, worst_file),
                             views=views[:1], wrap=3, pictures=pictures)
        figures.insert(0, worst_file)
    return figures, shown


def plot_dense_methods(template: tuple, meshes: dict, vertex_maps: dict, errors: dict, out_dir: str,
                       views: tuple[int, ...] = (0, 1), *, max_poses: int = 4) -> list[str]:
    """Per dense method, the template coloured by its coordinates and up to ``max_poses`` test poses coloured by
    that function pulled back through the method's map, best .. worst by ``errors`` (``dense_<method>.png``).

    Args:
        template: (V, F); meshes: {pose: (V, F)}.
        vertex_maps: {method: {pose: (n_template,) int target vertex per template vertex, -1 = none}}.
        errors: {method: {pose: error or None}} (None: no truth; such poses come last, uncaptioned).
    Returns the file names written.
    """
    figures = []
    for method, maps in vertex_maps.items():
        err = errors.get(method, {})
        order = sorted(maps, key=lambda m: (err.get(m) is None, err.get(m) or 0.0, m))
        poses = spread_best_to_worst(order, k=max_poses)
        captions = {m: f"mean geodesic error {err[m]:.3f}" for m in poses if err.get(m) is not None}
        file = f"dense_{method}.png"
        plot_dense_panels(template, {m: meshes[m] for m in poses}, {m: maps[m] for m in poses}, captions,
                          f"{method}: template coordinates as RGB, pulled back through the dense map "
                          "(best .. worst pose)", os.path.join(out_dir, file), views=views)
        figures.append(file)
    return figures
