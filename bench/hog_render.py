"""Throughput of the image side of alignment: ray-cast rendering and HOG features.

Run ``python bench/hog_render.py`` from the repository root. ``bench/alignment.py`` imports
``bench_hog`` and ``bench_render``. Timings are wall-clock on whatever the machine is doing, best of
a few repeats to damp noise from other processes.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from corr_core.open3d_loader import load_open3d  # noqa: E402
from corr_core.alignment.hog import hog_dollar, hog_features, hog_skimage  # noqa: E402
from corr_core.geometry.mesh_io import normalize_mesh  # noqa: E402
from corr_core.alignment.render import render_views  # noqa: E402
from corr_core.geometry.primitives import rotate_about_y  # noqa: E402


def benchmark_mesh(n_triangles: int = 15000) -> tuple[np.ndarray, np.ndarray]:
    """A normalized torus with about ``n_triangles`` triangles (exactly 15000 by default).

    Returns:
        V: (n, 3) float64, F: (m, 3) int64.
    """
    o3d = load_open3d()
    tubular = 75
    radial = max(3, round(n_triangles / (2 * tubular)))
    mesh = o3d.geometry.TriangleMesh.create_torus(
        torus_radius=1.0, tube_radius=0.4, radial_resolution=radial, tubular_resolution=tubular
    )
    V = rotate_about_y(np.asarray(mesh.vertices), 0.3) @ np.array([[1, 0, 0], [0, 0.8, 0.6], [0, -0.6, 0.8]])
    V, _, _ = normalize_mesh(V)
    return V, np.asarray(mesh.triangles, dtype=np.int64)


def _best_time(function, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best


def bench_render(
    n_meshes: int = 5, n_views: int = 16, image_size: int = 120, n_triangles: int = 15000
) -> dict:
    """Render ``n_views`` views of a ~15k-triangle mesh ``n_meshes`` times (rotated each time).

    Returns:
        dict with n_triangles, n_views, image_size, seconds_per_mesh (all views, incl. BVH build; best
        over the meshes), views_per_s.
    """
    V, F = benchmark_mesh(n_triangles)
    render_views(V, F, n_views=n_views, image_size=image_size)  # warm-up (open3d import, threads)
    times = []
    for k in range(n_meshes):
        Vk = rotate_about_y(V, 0.1 * (k + 1))
        start = time.perf_counter()
        render_views(Vk, F, n_views=n_views, image_size=image_size)
        times.append(time.perf_counter() - start)
    seconds = float(np.min(times))
    return {
        "n_triangles": int(len(F)),
        "n_views": n_views,
        "image_size": image_size,
        "seconds_per_mesh": seconds,
        "seconds_per_mesh_median": float(np.median(times)),
        "views_per_s": n_views / seconds,
    }


def bench_hog(n_images: int = 200, image_size: int = 120, repeats: int = 3) -> dict:
    """HOG throughput on rendered views: hog_dollar (per image and batched) vs skimage's hog.

    Returns:
        dict with n_images, image_size, dollar_images_per_s (one call per image),
        dollar_batch_images_per_s (one ``hog_features`` call on the stack), skimage_images_per_s,
        speedup_vs_skimage (per-image dollar / skimage), dims {"dollar": 8100, "skimage": 13689}.
    """
    V, F = benchmark_mesh(3000)
    views = render_views(V, F, n_views=16, image_size=image_size)
    images = np.concatenate([views] * (n_images // len(views) + 1))[:n_images]

    t_dollar = _best_time(lambda: [hog_dollar(image) for image in images], repeats)
    t_batch = _best_time(lambda: hog_features(images, method="dollar"), repeats)
    n_skimage = max(1, n_images // 2)  # skimage is slower; time half as many
    t_skimage = _best_time(lambda: [hog_skimage(image) for image in images[:n_skimage]], repeats)
    dollar_rate = n_images / t_dollar
    skimage_rate = n_skimage / t_skimage
    return {
        "n_images": n_images,
        "image_size": image_size,
        "dollar_images_per_s": dollar_rate,
        "dollar_batch_images_per_s": n_images / t_batch,
        "skimage_images_per_s": skimage_rate,
        "speedup_vs_skimage": dollar_rate / skimage_rate,
        "dims": {"dollar": int(hog_dollar(images[0]).size), "skimage": int(hog_skimage(images[0]).size)},
    }


if __name__ == "__main__":
    render = bench_render()
    print(
        f"render: {render['n_views']} views of {render['n_triangles']} triangles at "
        f"{render['image_size']}px: {render['seconds_per_mesh']:.3f} s best "
        f"({render['seconds_per_mesh_median']:.3f} s median), {render['views_per_s']:.0f} views/s"
    )
    hog = bench_hog()
    print(
        f"hog at {hog['image_size']}px: dollar {hog['dollar_images_per_s']:.0f} img/s "
        f"(batched {hog['dollar_batch_images_per_s']:.0f} img/s, {hog['dims']['dollar']} values), "
        f"skimage {hog['skimage_images_per_s']:.0f} img/s ({hog['dims']['skimage']} values), "
        f"ratio {hog['speedup_vs_skimage']:.2f}x"
    )
