"""Procedural chair collection with known azimuths (deterministic by seed, no downloads).

Canonical chair frame (what ``make_chair`` returns): y is up, the seat faces +z (a sitter looks towards +z), the
backrest is at -z, the centre of the axis-aligned bounding box is the origin and the largest bounding-box side is 1.

Written collection: chair ``NNN.obj`` is the canonical chair rotated about +y by
``azimuth = azimuth_steps * 2*pi / views`` with the standard right-handed rotation ``Ry(azimuth)``:
``x' = cos(a) x + sin(a) z``, ``y' = y``, ``z' = -sin(a) x + cos(a) z``. Un-rotating by ``-azimuth`` gives the
canonical chair back.

Chairs are unions of boxes and cylinders (parts overlap, meshes are not watertight, like real models). Boxes are
either "welded" (shared corner/edge vertices) or "faceted" (each box side has its own vertices, as in many
exported models); some chairs share parts (rear legs continuing into the backrest posts).
"""
from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from corr_core.geometry.mesh_io import save_obj
from corr_core.geometry.primitives import rotate_about_y

# ---------------------------------------------------------------------------------------------------------------
# primitives


def _grid_quad(corner: np.ndarray, du: np.ndarray, dv: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """A (k x k)-cell planar quad grid, triangulated. Returns V: ((k+1)^2, 3), F: (2k^2, 3), normal du x dv."""
    s = np.linspace(0.0, 1.0, k + 1)
    uu, vv = np.meshgrid(s, s, indexing="ij")
    V = corner + uu.reshape(-1, 1) * du + vv.reshape(-1, 1) * dv
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    a = (i * (k + 1) + j).ravel()
    b, c, d = a + (k + 1), a + (k + 2), a + 1
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return V, F


def box(center, half, R=None, *, k: int = 2, welded: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Triangulated box. center: (3,), half: (3,) half extents, R: (3,3) rotation (columns = box axes).

    Each side is a k x k grid (12 k^2 triangles). ``welded`` merges coincident vertices of neighbouring sides.
    Returns V: (n,3) float, F: (12k^2, 3) int, outward-oriented.
    """
    center, half = np.asarray(center, float), np.asarray(half, float)
    R = np.eye(3) if R is None else np.asarray(R, float)
    parts = []
    for axis in range(3):
        u_ax, v_ax = (axis + 1) % 3, (axis + 2) % 3
        for sign in (-1.0, 1.0):
            e = np.eye(3)
            n, u, v = e[axis] * sign, e[u_ax], e[v_ax]
            if sign < 0:
                u, v = v, u  # keep du x dv pointing outward
            corner = n - u - v
            parts.append(_grid_quad(corner, 2 * u, 2 * v, k))
    V, F = merge_parts(parts)
    if welded:
        V, F = weld(V, F)
    return (V * half) @ R.T + center, F


def cylinder(a, b, radius: float, *, segments: int = 12, rings: int = 1, radius_b: float | None = None,
             ) -> tuple[np.ndarray, np.ndarray]:
    """Capped (possibly tapered) cylinder from point a (3,) to point b (3,). Returns V: (n,3), F: (m,3),
    outward-oriented (sides and caps)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    axis = b - a
    length = np.linalg.norm(axis)
    w = axis / length
    helper = np.array([1.0, 0, 0]) if abs(w[0]) < 0.9 else np.array([0, 0, 1.0])
    u = np.cross(w, helper)
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    rb = radius if radius_b is None else radius_b
    t = np.linspace(0.0, 1.0, rings + 1)
    theta = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    r = radius + (rb - radius) * t
    ring_pts = (a + t[:, None, None] * axis
                + r[:, None, None] * (np.cos(theta)[None, :, None] * u + np.sin(theta)[None, :, None] * v))
    V = np.concatenate([ring_pts.reshape(-1, 3), a[None], b[None]])
    ca, cb = len(V) - 2, len(V) - 1
    i, j = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
    p = i * segments + j
    q = i * segments + (j + 1) % segments
    # counter-clockwise seen from outside (theta grows counter-clockwise about the axis): normals point outward
    side = np.concatenate([np.stack([p, q + segments, p + segments], -1).reshape(-1, 3),
                           np.stack([p, q, q + segments], -1).reshape(-1, 3)])
    j = np.arange(segments)
    cap_a = np.stack([np.full(segments, ca), (j + 1) % segments, j], 1)
    top = rings * segments
    cap_b = np.stack([np.full(segments, cb), top + j, top + (j + 1) % segments], 1)
    return V, np.concatenate([side, cap_a, cap_b]).astype(np.int64)


def merge_parts(parts) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate [(V_i, F_i), ...] into one mesh (no welding)."""
    Vs, Fs, offset = [], [], 0
    for V, F in parts:
        Vs.append(V)
        Fs.append(F + offset)
        offset += len(V)
    return np.concatenate(Vs), np.concatenate(Fs).astype(np.int64)


def weld(V: np.ndarray, F: np.ndarray, *, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices that coincide up to ``tol``; drop faces that become degenerate. Keeps first-seen order."""
    key = np.round(V / tol).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    Vw = V[first[order]]
    Fw = rank[inverse.ravel()][F]
    keep = (Fw[:, 0] != Fw[:, 1]) & (Fw[:, 1] != Fw[:, 2]) & (Fw[:, 0] != Fw[:, 2])
    return Vw, Fw[keep]


def rot_x(angle: float) -> np.ndarray:
    """(3,3) rotation about +x by ``angle`` radians (right-handed)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


# ---------------------------------------------------------------------------------------------------------------
# chair


def make_chair(rng: np.random.Generator, kind: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A random chair-like triangle mesh in the canonical frame (y up, backrest at -z, facing +z).

    Args:
        rng: the random generator (consumed; the same state gives the same chair).
        kind: "legs" (four legs), "pedestal" (office chair: column + star base) or None (drawn from rng,
            about 1 in 10 pedestal).
    Returns:
        V: (n, 3) float, bbox-centred with largest bbox side 1; F: (m, 3) int (about 500-3000 triangles).
    """
    if kind is None:
        kind = "pedestal" if rng.random() < 0.1 else "legs"
    welded = bool(rng.random() < 0.5)
    W = rng.uniform(0.40, 0.60)           # seat width (x)
    D = rng.uniform(0.38, 0.55)           # seat depth (z)
    T = rng.uniform(0.03, 0.08)           # seat thickness
    H = rng.uniform(0.38, 0.50)           # seat top height
    back_h = rng.uniform(0.25, 0.65)      # backrest height above seat
    tilt = np.deg2rad(rng.uniform(0.0, 22.0))  # backrest leaning back
    back_style = rng.choice(["solid", "vertical_slats", "horizontal_slats", "frame"])
    back_t = rng.uniform(0.025, 0.06)
    has_arms = bool(rng.random() < 0.3)
    leg_round = bool(rng.random() < 0.4)
    leg_w = rng.uniform(0.025, 0.05)
    splay = np.deg2rad(rng.uniform(0.0, 8.0)) if kind == "legs" else 0.0
    stretchers = kind == "legs" and bool(rng.random() < 0.4)
    posts_shared = kind == "legs" and back_style in ("frame", "vertical_slats") and bool(rng.random() < 0.6)

    parts = []
    seat_bottom = H - T
    seat_rounded = bool(rng.random() < 0.25)
    if seat_rounded:  # round/ellipse-ish seat: a flat cylinder scaled in z
        Vs, Fs = cylinder([0, seat_bottom, 0], [0, H, 0], W / 2, segments=24)
        Vs[:, 2] *= D / W
        parts.append((Vs, Fs))
    else:
        parts.append(box([0, H - T / 2, 0], [W / 2, T / 2, D / 2], k=4, welded=welded))

    # backrest: built in a local frame with its bottom edge at the back of the seat, then tilted about x
    back_parts = []
    bw = W * rng.uniform(0.85, 1.0)
    if back_style == "solid":
        back_parts.append(box([0, back_h / 2, 0], [bw / 2, back_h / 2, back_t / 2], k=4, welded=welded))
    else:
        post_w = rng.uniform(0.025, 0.045)
        rail_h = rng.uniform(0.04, 0.09)
        for sx in (-1, 1):
            back_parts.append(box([sx * (bw / 2 - post_w / 2), back_h / 2, 0], [post_w / 2, back_h / 2, back_t / 2],
                                  k=3, welded=welded))
        back_parts.append(box([0, back_h - rail_h / 2, 0], [bw / 2, rail_h / 2, back_t / 2], k=3, welded=welded))
        inner_w = bw - 2 * post_w
        if back_style == "vertical_slats":
            n_slats = int(rng.integers(2, 6))
            slat_w = inner_w / (2 * n_slats + 1)
            xs = -inner_w / 2 + slat_w * (2 * np.arange(n_slats) + 1.5)
            for x in xs:
                back_parts.append(box([x, (back_h - rail_h) / 2, 0], [slat_w / 2, (back_h - rail_h) / 2, back_t / 3],
                                      k=2, welded=welded))
        elif back_style == "horizontal_slats":
            n_slats = int(rng.integers(1, 4))
            ys = np.linspace(0.15, 0.75, n_slats) * (back_h - rail_h)
            for y in ys:
                back_parts.append(box([0, y, 0], [inner_w / 2 + 1e-3, rail_h / 3, back_t / 3], k=2, welded=welded))
    Rb = rot_x(-tilt)  # bottom stays at the seat, top moves to -z
    back_origin = np.array([0.0, H, -D / 2 + back_t / 2])
    for V, F in back_parts:
        parts.append((V @ Rb.T + back_origin, F))

    # legs
    if kind == "legs":
        inset = rng.uniform(0.0, 0.05)
        shrink = 0.7 if seat_rounded else 1.0  # keep the legs under a round seat
        corners = [(sx * shrink * (W / 2 - inset - leg_w / 2), sz * shrink * (D / 2 - inset - leg_w / 2))
                   for sx in (-1, 1) for sz in (-1, 1)]
        feet = []
        for x, z in corners:
            foot = np.array([x + np.sign(x) * seat_bottom * np.tan(splay), 0.0, z + np.sign(z) * seat_bottom * np.tan(splay)])
            top = np.array([x, seat_bottom, z])
            if posts_shared and z < 0 and tilt < np.deg2rad(4):
                top = np.array([x, H + back_h, z])  # rear leg continues as a backrest post
            feet.append(foot)
            if leg_round:
                parts.append(cylinder(foot, top, leg_w / 2, segments=10, rings=3, radius_b=leg_w / 2 * rng.uniform(1.0, 1.3)))
            else:
                mid, axis = (foot + top) / 2, top - foot
                R = _frame_with_y(axis)
                parts.append(box(mid, [leg_w / 2, np.linalg.norm(axis) / 2, leg_w / 2], R, k=2, welded=welded))
        if stretchers:
            y = seat_bottom * rng.uniform(0.2, 0.4)
            r = leg_w * 0.3
            for a, b in ((0, 1), (2, 3), (0, 2), (1, 3)):
                pa = np.array(corners[a] + (0.0,))[[0, 2, 1]]
                pb = np.array(corners[b] + (0.0,))[[0, 2, 1]]
                pa[1] = pb[1] = y
                parts.append(cylinder(pa, pb, r, segments=8))
    else:  # pedestal office chair: column, star base with casters
        col_r = rng.uniform(0.025, 0.04)
        base_y = rng.uniform(0.05, 0.08)
        parts.append(cylinder([0, base_y, 0], [0, seat_bottom, 0], col_r, segments=16, rings=2))
        parts.append(cylinder([0, seat_bottom - 0.05, 0], [0, seat_bottom, 0], col_r * 2.2, segments=16))
        n_arms = 5
        reach = rng.uniform(0.25, 0.33)
        phase = rng.uniform(0, 2 * np.pi)
        for k in range(n_arms):
            ang = phase + 2 * np.pi * k / n_arms
            tip = np.array([reach * np.cos(ang), base_y, reach * np.sin(ang)])
            parts.append(cylinder([0, base_y + 0.01, 0], tip, 0.022, segments=8, radius_b=0.014))
            parts.append(cylinder(tip + [0, -0.005, 0], tip + [0, -base_y + 0.005, 0], 0.022, segments=10))

    # arms: a horizontal rest on two supports (or one front support if the back is tall)
    if has_arms:
        arm_h = min(rng.uniform(0.18, 0.26), 0.65 * back_h)
        arm_w = rng.uniform(0.04, 0.07)
        arm_len = D * rng.uniform(0.75, 0.95)
        for sx in (-1, 1):
            x = sx * (W / 2 + arm_w / 2 - 0.01)
            zc = -D / 2 + arm_len / 2
            parts.append(box([x, H + arm_h, zc], [arm_w / 2, 0.02, arm_len / 2], k=3, welded=welded))
            for z in (zc + arm_len / 2 - 0.04, zc - arm_len / 2 + 0.04):
                parts.append(box([x, H + arm_h / 2, z], [0.015, arm_h / 2, 0.015], k=1, welded=welded))

    V, F = merge_parts(parts)
    c = 0.5 * (V.min(0) + V.max(0))
    s = (V.max(0) - V.min(0)).max()
    return (V - c) / s, F


def _frame_with_y(axis: np.ndarray) -> np.ndarray:
    """(3,3) rotation whose second column is the unit ``axis`` (boxes stretched along local y)."""
    y = axis / np.linalg.norm(axis)
    x = np.cross(y, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-8:
        x = np.array([1.0, 0, 0])
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    return np.stack([x, y, z], 1)


def chair_rng(seed: int, index: int) -> np.random.Generator:
    """The generator used for the shape of chair ``index`` (1-based) of the collection with ``seed``."""
    return np.random.default_rng([seed, index])


def chair_kind(index: int) -> str:
    """Kind of chair ``index`` (1-based): chairs 6, 18, 30, .. (one in 12) are pedestal office chairs."""
    return "pedestal" if index % 12 == 6 else "legs"


def canonical_chair(seed: int, index: int) -> tuple[np.ndarray, np.ndarray]:
    """The un-rotated chair ``index`` (1-based) of ``write_chair_collection(seed=seed)``.

    Equals ``make_chair(chair_rng(seed, index), kind=chair_kind(index))``; independent of the collection size.
    """
    return make_chair(chair_rng(seed, index), kind=chair_kind(index))


def collection_azimuths(n: int, seed: int, views: int, continuous: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Azimuths of the ``n`` shapes of a collection: (steps (n,) int in 0..views-1, degrees (n,) float).

    Drawn from ``np.random.default_rng([seed, 0])``: steps uniform on 0..views-1 (degrees = steps * 360/views),
    or with ``continuous`` degrees uniform in [0, 360) and steps = the nearest view (round(deg / step) % views).
    """
    rng = np.random.default_rng([seed, 0])
    if not continuous:
        steps = rng.integers(0, views, size=n)
        return steps, steps * 360.0 / views
    deg = rng.uniform(0.0, 360.0, size=n)
    return np.rint(deg * views / 360.0).astype(np.int64) % views, deg


def write_ground_truth(path: str | os.PathLike, names: list[str], steps: np.ndarray, deg: np.ndarray,
                       extra: dict[str, list] | None = None, whole_steps: bool = True) -> None:
    """ground_truth.csv: shape, azimuth_steps (nearest view), azimuth_deg (the exact angle: 6 significant
    digits for whole view steps, 6 decimals for continuous azimuths), then ``extra`` columns {column: (n,) values}."""
    extra = extra or {}
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["shape", "azimuth_steps", "azimuth_deg", *extra])
        for k, (name, st, d) in enumerate(zip(names, steps, deg)):
            w.writerow([name, int(st), f"{d:.6g}" if whole_steps else f"{d:.6f}",
                        *(col[k] for col in extra.values())])


def write_chair_collection(out_dir: str | os.PathLike, *, n: int = 24, seed: int = 0, views: int = 16,
                           continuous: bool = False) -> dict:
    """Write ``n`` chairs ``001.obj``.. rotated by random known azimuths, plus ``ground_truth.csv``.

    Chair i is ``canonical_chair(seed, i)`` rotated by ``Ry(azimuth_deg[i])``; the azimuths are those of
    ``collection_azimuths(n, seed, views, continuous)``: whole view steps by default, any angle in [0, 360)
    with ``continuous`` (azimuth_steps is then the nearest view).
    Returns (JSON-serialisable): {"out_dir", "files": [paths], "names": ["001", ...], "azimuth_steps": [n ints],
    "azimuth_deg": [n floats], "views": views, "ground_truth": path of the csv}.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    steps, deg = collection_azimuths(n, seed, views, continuous)
    names, files = [], []
    for i in range(1, n + 1):
        V, F = canonical_chair(seed, i)
        name = f"{i:03d}"
        path = out / f"{name}.obj"
        angle = steps[i - 1] * 2 * np.pi / views if not continuous else np.deg2rad(deg[i - 1])
        save_obj(path, rotate_about_y(V, angle), F)
        names.append(name)
        files.append(str(path))
    gt = out / "ground_truth.csv"
    write_ground_truth(gt, names, steps, deg, whole_steps=not continuous)
    return {"out_dir": str(out), "files": files, "names": names, "azimuth_steps": [int(v) for v in steps],
            "azimuth_deg": [float(v) for v in deg], "views": views, "ground_truth": str(gt)}
