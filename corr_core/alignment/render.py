"""Grayscale views of a mesh from cameras circling the y axis (CPU ray casting with Open3D).

World frame: y is up. ``rotate_about_y(V, a)`` applies the standard right-handed rotation
``Ry(a) = [[cos a, 0, sin a], [0, 1, 0], [-sin a, 0, cos a]]``, so a positive angle turns +x toward -z
and +z toward +x (counter-clockwise seen from +y looking down).

View order: view k is taken by camera k = Ry(k * 2 pi / n_views) applied to camera 0; camera 0 sits on
the +z side, ``elevation_deg`` above the xz plane, looking at the origin, with image-up the
projection of +y. Because camera k is camera 0 rotated by Ry(k * step), rotating the *shape* by
Ry(s * step) moves what camera k saw to camera k + s:

    render_views(rotate_about_y(V, s * 2 pi / n), F)[(k + s) % n] == render_views(V, F)[k]

(exactly up to floating-point rounding of the rays, since the ray sets are themselves rotated copies).
Projection is orthographic with a square window of half-width ``margin`` world units centred on the
origin, so a normalized mesh (centred, radius <= 1) is always fully in view.

Ray casting: all views in one call, and only the rays of pixels inside the image-plane bounding box of some
face (``pixels_in_face_boxes``; the other rays cannot hit anything): the same rays as casting every pixel's,
hence the same hits, at a fraction of the cost (a chair covers ~1/6 of its views).

Shading: white background (1.0); surface = ambient + diffuse * |n . d| with d the ray direction (a
headlight attached to the camera) and n the face normal. The absolute value makes shading
double-sided, as the meshes are not watertight and their normals are not consistently oriented.
"""
from __future__ import annotations

import functools
from typing import Sequence

import numpy as np

from corr_core.open3d_loader import load_open3d
from corr_core.geometry.primitives import face_normals, rotation_about_y


def camera_frames(*, n_views: int = 16, elevation_deg: float = 20.0) -> np.ndarray:
    """Orthonormal camera frames of the view circle.

    Args:
        n_views: number of cameras, 2 pi / n_views apart in azimuth.
        elevation_deg: camera elevation above the xz plane, degrees.
    Returns:
        (n_views, 3, 3) float64: rows [right, up, back] of each camera; ``back`` points from the origin
        to the camera (the camera looks along -back). Frame k = Ry(k * 2 pi / n_views) @ frame 0.
    """
    elevation = np.deg2rad(elevation_deg)
    back = np.array([0.0, np.sin(elevation), np.cos(elevation)])
    right = np.array([1.0, 0.0, 0.0])
    up = np.cross(back, right)  # = (0, cos e, -sin e): +y tilted away from the camera
    frame0 = np.stack([right, up, back])  # rows
    step = 2.0 * np.pi / n_views
    return np.stack([frame0 @ rotation_about_y(k * step).T for k in range(n_views)])


def view_rays(
    *, n_views: int = 16, image_size: int = 120, elevation_deg: float = 20.0, margin: float = 1.05,
    views: Sequence[int] | None = None,
) -> np.ndarray:
    """Orthographic rays of every pixel of every view (or of the cameras ``views`` only).

    Args:
        n_views, elevation_deg: see ``camera_frames``.
        image_size: pixels per side (square images).
        margin: half-width of the square view window in world units (1.05 keeps a unit sphere in view).
        views: indices of the cameras (of ``n_views``) whose rays are made, in this order; None: all. A camera's
            rays are the same bit for bit either way.
    Returns:
        (n_views or len(views), image_size, image_size, 6) float32 rays [origin, unit direction]; row 0 is the
        top of the image; origins lie 3 units from the origin, outside the unit sphere.
    """
    frames = camera_frames(n_views=n_views, elevation_deg=elevation_deg)
    if views is not None:
        frames = frames[np.asarray(views, dtype=np.int64)]
    centres = (np.arange(image_size) + 0.5) / image_size * 2.0 - 1.0
    u = centres * margin  # image x (columns, left -> right)
    v = -centres * margin  # image y (rows, top -> bottom), so world-up is image-up
    right, up, back = frames[:, 0], frames[:, 1], frames[:, 2]
    origins = (
        3.0 * back[:, None, None, :]
        + u[None, None, :, None] * right[:, None, None, :]
        + v[None, :, None, None] * up[:, None, None, :]
    )
    directions = np.broadcast_to(-back[:, None, None, :], origins.shape)
    return np.concatenate([origins, directions], axis=-1).astype(np.float32)


@functools.lru_cache(maxsize=8)
def _cached_view_rays(n_views: int, image_size: int, elevation_deg: float, margin: float) -> np.ndarray:
    """``view_rays`` flattened to (n_views * size * size, 6), cached (read-only): the rays only depend on the
    camera parameters."""
    rays = view_rays(n_views=n_views, image_size=image_size, elevation_deg=elevation_deg, margin=margin).reshape(-1, 6)
    rays.setflags(write=False)
    return rays


def pixels_in_face_boxes(
    V: np.ndarray, F: np.ndarray, *, n_views: int = 16, image_size: int = 120, elevation_deg: float = 20.0,
    margin: float = 1.05,
) -> np.ndarray:
    """Pixels whose ray can hit a face: those inside the image-plane bounding box of some face, per view.

    A ray of view k runs along -back_k through the point u * right_k + v * up_k (``view_rays``), so it can
    only meet face f if (u, v) lies in the box spanned by the projections (V @ right_k, V @ up_k) of f's
    corners. Each box is grown by half a pixel (far beyond the float32 rounding of rays and vertices, ~1e-6
    world units), so every pixel outside all boxes is certainly a miss. The union of the boxes is built with
    a 2D difference array (+-1 at the box corners, then cumulative sums): no loop over faces or views.

    Args:
        V: (n, 3) float vertices; F: (m, 3) int triangles; the other arguments as in ``view_rays``.
    Returns:
        (n_views, image_size, image_size) bool, True where a ray must be cast.
    """
    frames = camera_frames(n_views=n_views, elevation_deg=elevation_deg)
    F = np.asarray(F)
    u = np.asarray(V, dtype=np.float64) @ frames[:, :2].reshape(-1, 3).T  # (n, 2 k): image x, y per view
    a, b, c = u[F[:, 0]].T, u[F[:, 1]].T, u[F[:, 2]].T  # (2 k, m): the three corners of every face
    low, high = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    pixel = 2.0 * margin / image_size
    grow = 0.5 * pixel
    # pixel centre j sits at x = ((j + 0.5) / size * 2 - 1) * margin, i.e. j = (x + margin) / pixel - 0.5;
    # row i at y = -((i + 0.5) / size * 2 - 1) * margin (rows run top -> bottom)
    col_lo = np.ceil((low[0::2] - grow + margin) / pixel - 0.5)  # (k, m)
    col_hi = np.floor((high[0::2] + grow + margin) / pixel - 0.5)
    row_lo = np.ceil((margin - high[1::2] - grow) / pixel - 0.5)
    row_hi = np.floor((margin - low[1::2] + grow) / pixel - 0.5)
    last = image_size - 1
    inside = (col_hi >= 0) & (col_lo <= last) & (row_hi >= 0) & (row_lo <= last)
    view = np.broadcast_to(np.arange(n_views)[:, None], inside.shape)[inside]
    c0 = np.clip(col_lo[inside], 0, last).astype(np.intp)
    c1 = np.clip(col_hi[inside], 0, last).astype(np.intp) + 1
    r0 = np.clip(row_lo[inside], 0, last).astype(np.intp)
    r1 = np.clip(row_hi[inside], 0, last).astype(np.intp) + 1
    side = image_size + 1
    top, bottom = view * (side * side) + r0 * side, view * (side * side) + r1 * side
    n_cells = n_views * side * side
    marks = (np.bincount(np.concatenate([top + c0, bottom + c1]), minlength=n_cells)
             - np.bincount(np.concatenate([top + c1, bottom + c0]), minlength=n_cells))
    marks = marks.astype(np.int32).reshape(n_views, side, side)
    count = np.cumsum(np.cumsum(marks, axis=1, dtype=np.int32), axis=2, dtype=np.int32)
    return count[:, :image_size, :image_size] > 0


def render_views(
    V: np.ndarray,
    F: np.ndarray,
    *, n_views: int = 16,
    image_size: int = 120,
    elevation_deg: float = 20.0,
    margin: float = 1.05,
    ambient: float = 0.1,
    diffuse: float = 0.75,
    supersample: int = 1,
) -> np.ndarray:
    """Render shaded grayscale views of a mesh from cameras on a circle around the y axis.

    See the module docstring for the world frame, the view order (shifting views == rotating the
    shape about y) and the shading model.

    Args:
        V: (n, 3) float vertices of a normalized mesh (centred at the origin, radius <= 1, y up).
        F: (m, 3) int triangles.
        n_views: views, 2 pi / n_views apart in azimuth.
        image_size: output pixels per side.
        elevation_deg: camera elevation above the xz plane, degrees.
        margin: half-width of the orthographic window, world units.
        ambient, diffuse: shade = ambient + diffuse * |n . d|; keep the sum < 1 so the object stays
            distinguishable from the white background.
        supersample: render at ``supersample`` x the resolution and box-average (anti-aliasing).
    Returns:
        (n_views, image_size, image_size) float32 in [0, 1], background 1.0.
    """
    V = np.asarray(V, dtype=np.float32)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError(f"V must be (n, 3), got shape {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise ValueError(f"F must be a non-empty (m, 3) triangle array, got shape {F.shape}")
    if F.min() < 0 or F.max() >= len(V):
        raise ValueError(f"F indexes vertices outside [0, {len(V)})")
    o3d = load_open3d()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(V), o3d.core.Tensor(F.astype(np.uint32)))

    size = image_size * supersample
    rays = _cached_view_rays(n_views, size, float(elevation_deg), float(margin))
    # one cast for all views, of the rays that can hit a face only (every other ray misses): the same rays,
    # so the same hits as casting them all, at a fraction of the cost (a chair covers ~1/6 of a view)
    cast = np.flatnonzero(pixels_in_face_boxes(V, F, n_views=n_views, image_size=size, elevation_deg=elevation_deg,
                                               margin=margin))
    images = np.ones((n_views, size, size), np.float32)
    if len(cast) == 0:
        return _downsample(images, image_size, supersample)
    face = scene.cast_rays(o3d.core.Tensor(rays[cast]))["primitive_ids"].numpy()  # (len(cast),) uint32
    hit = face != scene.INVALID_ID
    pixel = cast[hit]
    view_of_hit = pixel // (size * size)

    # the headlight direction is constant per view: |n . d| for every (face, view) pair at once
    backs = camera_frames(n_views=n_views, elevation_deg=elevation_deg)[:, 2].astype(np.float32)  # -d per view
    cosine = np.abs(np.einsum("fi,vi->fv", face_normals(V, F).astype(np.float32), backs))  # (m, n_views)
    shade = ambient + diffuse * cosine
    images.reshape(-1)[pixel] = shade[face[hit], view_of_hit]
    return _downsample(images, image_size, supersample)


def _downsample(images: np.ndarray, image_size: int, supersample: int) -> np.ndarray:
    """Box-average (n_views, size, size) renders at ``supersample`` x resolution down to ``image_size``."""
    if supersample > 1:
        n_views = len(images)
        images = images.reshape(n_views, image_size, supersample, image_size, supersample).mean(axis=(2, 4))
    return images
