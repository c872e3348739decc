"""Stage wiring for problem 1: joint azimuthal alignment of a shape collection.

views (per shape) -> hog (per shape) -> pairs (per tile of shape pairs: C_ij(theta)) -> solve (MRF)
-> evaluate (metrics) / export (aligned OBJs, views, alignment.csv, zips) / figures.
The algorithms live in corr_core; these functions only load, call and store.
"""
from __future__ import annotations

import csv
import os
import shutil
import zipfile

import numpy as np

from corr_core.alignment import azimuth

from corr_core.alignment import pair_costs as circular

from corr_core import mrf

from corr_core.alignment import sync
from corr_core.alignment.hog import draw_hog, hog_features
from corr_core.geometry.mesh_io import MeshError, load_mesh, normalize_mesh, save_obj
from corr_core.alignment.render import render_views, rotate_about_y
from corr_core.alignment.views import load_view_stack

from stages.registry import register

MESH_EXTENSIONS = (".obj", ".off", ".ply")


def _input_kind(files: list[str]) -> str:
    exts = {os.path.splitext(f)[1].lower() for f in files}
    if len(files) == 1 and exts <= set(MESH_EXTENSIONS):
        return "mesh"
    if exts == {".png"}:
        return "views"
    raise ValueError(f"cannot tell whether {files[0]} ... is a mesh or a set of view images "
                     f"(extensions {sorted(exts)}); give one mesh (.obj/.off/.ply) or NNN_V.png views per shape")


@register("align.views", fanout="item")
def views(files, *, n_views: int = 16, image_size: int = 120, elevation_deg: float = 20.0,
          center: str = "area") -> dict:
    """Views of one shape: render a mesh (normalized: area centroid at the origin, unit radius) or load
    pre-rendered views.

    files: a list with one mesh path, or the shape's NNN_V.png paths in view order.
    Returns {"views": (V, S, S) uint8 grayscale (255 = white background), "kind": "mesh"|"views"}.
    """
    files = [files] if isinstance(files, str) else list(files)
    kind = _input_kind(files)
    if kind == "mesh":
        V, F = load_mesh(files[0])
        Vn, _, _ = normalize_mesh(V, center=center, F=F)
        images = render_views(Vn, F, n_views=n_views, image_size=image_size, elevation_deg=elevation_deg)
    else:
        if len(files) != n_views:
            raise ValueError(f"{os.path.dirname(files[0])}: shape has {len(files)} views, expected n_views={n_views}")
        images = load_view_stack(files, size=image_size)
    if not np.all(np.isfinite(images)):
        raise ValueError(f"{files[0]}: views contain NaN values")
    return {"views": np.clip(np.rint(images * 255.0), 0, 255).astype(np.uint8), "kind": kind}


@register("align.hog", fanout="item")
def hog(views, *, method: str = "dollar") -> np.ndarray:
    """Per-shape feature: HoG of each view, (V, D) float32 (Dollar-compatible 15x15x36 at 120x120 by default)."""
    images = views["views"].astype(np.float32) / 255.0
    return hog_features(images, method=method).astype(np.float32)


@register("align.pair_costs", fanout="pair", mirror=circular.mirror_pair_costs)
def pair_costs(A, B) -> np.ndarray:
    """C: (a, b, V) float32, C_ij(theta) = sum_v ||F_i[v] - F_j[v+theta]||^2 for a tile of shape pairs."""
    return circular.pair_costs(A, B)


def _sigma(C: np.ndarray, sigma, sigma_scale: float) -> float:
    base = circular.auto_sigma(C) if sigma in (None, "auto") else float(sigma)
    return float(base * sigma_scale)


def _neighbors(C: np.ndarray, knn: int):
    return circular.nearest_shapes(C, knn) if knn and knn < len(C) - 1 else None


def solve_labels(C: np.ndarray, solver: str, sigma: float, seed: int, knn: int = 0, op=None) -> dict:
    """Labels (N,) for pair costs C (N,N,V) with the chosen solver, plus energy diagnostics.

    op: the MRF operator of (C, sigma, knn) when the caller already built it (its kernel is N*N*V exps)."""
    N, _, V = C.shape
    neighbors = _neighbors(C, knn)
    if op is None:
        op = circular.CirculantPairwise(C, sigma, neighbors)
    unary = circular.uniform_unary(N, V, seed)
    out: dict = {}
    if solver == "lh":
        res = mrf.solve_lh(op, unary, compute_bound=False)
        labels = res.labels
        out.update(iterations=int(res.iterations), converged=bool(res.converged),
                   relaxed_value=float(res.relaxed_value), energy_before_climb=float(res.energy_before_climb))
    elif solver == "spectral":
        labels = sync.spectral_sync_operator(op)  # same as sync.spectral_sync(C, sigma, neighbors), one kernel
    elif solver == "ppm":
        labels, _ = sync.projected_power(C, sigma, neighbors=neighbors)
    else:
        raise ValueError(f"unknown solver '{solver}' (use lh, spectral or ppm)")
    labels = np.asarray(labels, dtype=np.int64)
    out.update(labels=labels, energy=float(mrf.energy(op, unary, labels)))
    return out


@register("align.solve", fanout="once")
def solve(costs, *, solver: str = "lh", sigma: float | str = "auto", sigma_scale: float = 1.0, seed: int = 0,
          knn: int = 0) -> dict:
    """Joint alignment: MRF over shapes with V labels (rotation offsets), W_ij = exp(-D_ij / sigma).

    costs: {"names": N names, "matrix": (N, N, V) C}. solver: "lh" (Leordeanu & Hebert + climbing),
    "spectral" (angular synchronization), "ppm" (projected power). sigma: "auto" = median over pairs of
    min_theta C_ij, times sigma_scale. knn > 0 keeps only each shape's k nearest shapes in the graph.
    Returns {"names", "labels" (N,) int, "sigma", "energy", "solver", ...}.
    """
    C = np.asarray(costs["matrix"])  # kept float32: no (N, N, V) float64 copy (1.6 GB -> 3.2 GB at N=5000)
    if not np.all(np.isfinite(C.min(axis=2))):  # min propagates NaN/inf; avoids an (N, N, V) bool temporary
        raise ValueError("pair costs contain NaN: a shape's features are broken")
    s = _sigma(C, sigma, sigma_scale)
    out = solve_labels(C, solver, s, seed, knn)
    out.update(names=list(costs["names"]), sigma=s, solver=solver, seed=seed, n_views=int(C.shape[2]), knn=int(knn))
    return out


def _read_ground_truth(path) -> dict[str, int] | None:
    if not path or not os.path.isfile(path):
        return None
    with open(path, encoding="utf-8") as fh:
        return {row["shape"]: int(row["azimuth_steps"]) for row in csv.DictReader(fh)}


def shift_costs(C: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """Pair costs after cyclically shifting shape i's views by shifts[i] (as if rotated by +shifts[i] steps):
    C'_ij(theta) = C_ij(theta + s_i - s_j)."""
    N, _, V = C.shape
    idx = (np.arange(V)[None, None, :] + shifts[:, None, None] - shifts[None, :, None]) % V
    return np.take_along_axis(C, idx, axis=2)


def _agreement(a: np.ndarray, b: np.ndarray, V: int) -> dict:
    """Exact and within-one-view agreement of two labelings up to one global offset."""
    return {"exact": float(azimuth.agreement_up_to_offset(a, b, V, tolerance=0)[0]),
            "within_one_view": float(azimuth.agreement_up_to_offset(a, b, V, tolerance=1)[0]), "n": int(len(a))}


def seed_stability(C: np.ndarray, solution: dict, seeds: list, op=None) -> dict:
    """Agreement (exact, up to one offset) with the solution of the labelings from other unary seeds.
    op: the solution graph's operator, if already built."""
    labels, V = np.asarray(solution["labels"]), C.shape[2]
    others = [solve_labels(C, solution["solver"], float(solution["sigma"]), int(s), int(solution.get("knn", 0)),
                           op)["labels"] for s in seeds if int(s) != solution["seed"]]
    agree = [azimuth.agreement_up_to_offset(r, labels, V)[0] for r in others]
    return {"min": float(min(agree)) if agree else 1.0, "mean": float(np.mean(agree)) if agree else 1.0,
            "n_seeds": len(others) + 1}


def equivariance(C: np.ndarray, solution: dict, shift_seed: int) -> float:
    """Shift every shape's views by a known random offset, solve again: fraction whose label moved by it."""
    N, _, V = C.shape
    shifts = np.random.default_rng(shift_seed).integers(0, V, N)
    shifted = solve_labels(shift_costs(C, shifts), solution["solver"], float(solution["sigma"]),
                           int(solution["seed"]), int(solution.get("knn", 0)))["labels"]
    return float(azimuth.agreement_up_to_offset(shifted, (np.asarray(solution["labels"]) + shifts) % V, V)[0])


def solver_quality(C: np.ndarray, solution: dict, peer_labels: dict, restarts: int, seed: int, op=None) -> dict:
    """Energies on the complete graph with the solution's unary terms: the answer, ICM from random starts,
    the best of ``restarts`` random restarts, each solver's labeling, a random labeling, and an upper bound.
    op: the complete graph's operator, if already built."""
    N, _, V = C.shape
    if op is None:
        op = circular.CirculantPairwise(C, float(solution["sigma"]))
    unary = circular.uniform_unary(N, V, int(solution["seed"]))
    rng = np.random.default_rng(seed)
    energy = lambda lab: float(mrf.energy(op, unary, lab))  # noqa: E731
    icm = [energy(mrf.icm(op, unary, mrf.random_labels(N, V, rng))) for _ in range(5)]
    quality = {"energy": energy(np.asarray(solution["labels"])), "icm_random_start_mean": float(np.mean(icm)),
               "best_of_random_restarts": float(mrf.best_of_random_restarts(op, unary, restarts, seed=seed)[1]),
               "upper_bound": float(mrf.upper_bound(op, unary)),
               "random_labeling": energy(mrf.random_labels(N, V, rng))}
    quality.update({f"energy_{peer}": energy(lab) for peer, lab in peer_labels.items()})
    return quality


@register("align.evaluate", fanout="once")
def evaluate(costs, solution, ground_truth=None, other=None, *, seeds: list = (0, 1, 2, 3, 4),
             shift_seed: int = 123, restarts: int = 20, compare_solvers: bool = True) -> dict:
    """Metrics of an alignment run (all agreements are up to one global offset).

    - labels {name: view index} and angle_deg;
    - seed_stability: agreement of the labelings from several unary seeds with the first;
    - equivariance: shift each shape's views by known random offsets, solve again, fraction whose label moved
      by exactly that offset;
    - solver_quality: energies of the answer, ICM from random starts, best of random restarts, each solver
      (lh, spectral, ppm when ``compare_solvers``), a random labeling, and an upper bound; agreement_with peers;
    - ground_truth (generated data): fraction exact and within one view (per solver too);
    - mode_agreement with another run's solution (e.g. meshes vs pre-rendered views) on common shapes.
    Re-solves use the solution's graph (``knn``); energies use the complete graph.
    """
    C = np.asarray(costs["matrix"])  # float32 as stored (the operators compute in float64)
    names, labels = list(solution["names"]), np.asarray(solution["labels"])
    N, _, V = C.shape
    sigma = float(solution["sigma"])
    neighbors = _neighbors(C, int(solution.get("knn", 0)))
    graph_op = circular.CirculantPairwise(C, sigma, neighbors)          # the solution's graph: re-solves
    full_op = graph_op if neighbors is None else circular.CirculantPairwise(C, sigma)   # energies, peers
    m: dict = {"n_shapes": N, "n_views": V, "solver": solution["solver"], "sigma": sigma,
               "labels": {n: int(l) for n, l in zip(names, labels)},
               "angle_deg": {n: float(l * 360.0 / V) for n, l in zip(names, labels)},
               "seed_stability": seed_stability(C, solution, list(seeds), graph_op),
               "equivariance": equivariance(C, solution, shift_seed)}
    peers = {}
    if compare_solvers:
        peers = {p: labels if p == solution["solver"] else
                 solve_labels(C, p, sigma, int(solution["seed"]), op=full_op)["labels"]
                 for p in ("lh", "spectral", "ppm")}
        m["agreement_with"] = {p: float(azimuth.agreement_up_to_offset(lab, labels, V)[0])
                               for p, lab in peers.items() if p != solution["solver"]}
    m["solver_quality"] = solver_quality(C, solution, peers, restarts, shift_seed, full_op)
    gt = _read_ground_truth(ground_truth)
    if gt:
        common = [i for i, n in enumerate(names) if n in gt]
        truth = np.array([gt[names[i]] for i in common])
        m["ground_truth"] = _agreement(labels[common], truth, V)
        for p, lab in peers.items():
            m["ground_truth"][f"exact_{p}"] = _agreement(lab[common], truth, V)["exact"]
    if other is not None:
        other_map = dict(zip(other["names"], np.asarray(other["labels"])))
        common = [i for i, n in enumerate(names) if n in other_map]
        if common:
            m["mode_agreement"] = _agreement(labels[common], np.array([other_map[names[i]] for i in common]), V)
    return m


def _aligned_view_index(label: int, V: int, k: int = 0) -> int:
    return int((k + label) % V)


@register("align.export", fanout="once", writes_files=True)
def export(shapes, solution, *, center: str = "area", out_dir: str) -> dict:
    """Aligned outputs: alignment.csv (shape, label, angle_deg); for meshes the aligned normalized OBJs and
    aligned_meshes.zip; for pre-rendered views each shape's optimally aligned view and aligned_views.zip."""
    names, labels = list(solution["names"]), np.asarray(solution["labels"])
    V = int(solution["n_views"])
    with open(os.path.join(out_dir, "alignment.csv"), "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["shape", "label", "angle_deg"])
        for n, l in zip(names, labels):
            w.writerow([n, int(l), f"{l * 360.0 / V:.2f}"])
    written = {"meshes": 0, "views": 0}
    mesh_dir, view_dir = os.path.join(out_dir, "aligned_meshes"), os.path.join(out_dir, "aligned_views")
    for n, l in zip(names, labels):
        files = shapes[n] if not isinstance(shapes[n], str) else [shapes[n]]
        if _input_kind(files) == "mesh":
            Vx, F = load_mesh(files[0])
            Vn, _, _ = normalize_mesh(Vx, center=center, F=F)
            os.makedirs(mesh_dir, exist_ok=True)
            save_obj(os.path.join(mesh_dir, f"{n}.obj"), rotate_about_y(Vn, -2 * np.pi * int(l) / V), F)
            written["meshes"] += 1
        else:
            os.makedirs(view_dir, exist_ok=True)
            src = files[_aligned_view_index(int(l), V)]
            shutil.copyfile(src, os.path.join(view_dir, f"{n}.png"))
            written["views"] += 1
    for folder, zname in ((mesh_dir, "aligned_meshes.zip"), (view_dir, "aligned_views.zip")):
        if os.path.isdir(folder):
            with zipfile.ZipFile(os.path.join(out_dir, zname), "w", zipfile.ZIP_DEFLATED) as z:
                for fn in sorted(os.listdir(folder)):
                    z.write(os.path.join(folder, fn), arcname=os.path.join(os.path.basename(folder), fn))
    return written


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _pick(names: list[str], wanted: list[str], k: int) -> list[str]:
    chosen = [n for n in wanted if n in names]
    return chosen if len(chosen) >= min(k, len(names)) else sorted(names)[:k]


def _save(fig, out_dir: str, name: str) -> str:
    """Save and close a matplotlib figure as ``out_dir/name``; returns ``name``."""
    plt = _plt()
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, name), dpi=90)
    plt.close(fig)
    return name


def _hog_cells(H: np.ndarray):
    """(h, w, 36) cells of a flattened Dollar HoG vector, or None for other layouts."""
    side = int(round(np.sqrt(H.size / 36)))
    return H.reshape(side, side, 36) if side * side * 36 == H.size else None


def _figure_hog(views, features, shapes: list[str], view_ids: list[int], V: int, out_dir: str) -> str:
    """Each shape's chosen views next to their HoG glyph drawings."""
    plt = _plt()
    fig, axes = plt.subplots(len(shapes), 2 * len(view_ids), figsize=(4.0 * len(view_ids), 2.1 * len(shapes)))
    axes = np.atleast_2d(axes)
    for r, n in enumerate(shapes):
        for c, k in enumerate(view_ids):
            axes[r, 2 * c].imshow(views[n]["views"][k % V], cmap="gray", vmin=0, vmax=255)
            axes[r, 2 * c].set_title(f"{n} view {k % V}", fontsize=8)
            cells = _hog_cells(np.asarray(features[n][k % V]))
            if cells is not None:
                axes[r, 2 * c + 1].imshow(draw_hog(cells), cmap="gray")
                axes[r, 2 * c + 1].set_title("HoG", fontsize=8)
    for ax in axes.ravel():
        ax.axis("off")
    return _save(fig, out_dir, "hog_drawings.png")


def _figure_dij(costs, a: str, b: str, V: int, out_dir: str) -> str:
    """Heat map of D_ij(t1, t2) = C_ij(t2 - t1) for shapes a, b."""
    plt = _plt()
    C = np.asarray(costs["matrix"])[costs["names"].index(a), costs["names"].index(b)]
    t = np.arange(V)
    fig, ax = plt.subplots(figsize=(5, 4.3))
    im = ax.imshow(C[(t[None, :] - t[:, None]) % V], cmap="viridis")
    ax.set_xlabel(f"label t2 of {b}")
    ax.set_ylabel(f"label t1 of {a}")
    ax.set_title(f"D_ij(t1,t2) = C_ij(t2-t1), {a} vs {b}")
    fig.colorbar(im, ax=ax)
    return _save(fig, out_dir, "dij_heatmap.png")


def _figure_view_pairs(views, features, a: str, b: str, out_dir: str) -> str:
    """The most and the least similar view pair of shapes a and b (squared HoG distance per view)."""
    plt = _plt()
    Fa, Fb = np.asarray(features[a], np.float64), np.asarray(features[b], np.float64)
    d = (Fa ** 2).sum(1)[:, None] + (Fb ** 2).sum(1)[None, :] - 2 * Fa @ Fb.T
    best, worst = np.unravel_index(np.argmin(d), d.shape), np.unravel_index(np.argmax(d), d.shape)
    fig, axes = plt.subplots(2, 2, figsize=(5, 5))
    for r, (pair, title) in enumerate(((best, "best"), (worst, "worst"))):
        for c, (shape, k) in enumerate(((a, pair[0]), (b, pair[1]))):
            axes[r, c].imshow(views[shape]["views"][k], cmap="gray", vmin=0, vmax=255)
            axes[r, c].set_title(f"{title}: {shape} view {k}" + (f" (d={d[pair]:.1f})" if c else ""), fontsize=8)
            axes[r, c].axis("off")
    return _save(fig, out_dir, "view_pairs_best_worst.png")


def _figure_grid(views, labels: dict, shapes: list[str], V: int, out_dir: str) -> str:
    """3x3 grid of aligned shapes: each shape's view at the common frame's view 0."""
    plt = _plt()
    fig, axes = plt.subplots(3, 3, figsize=(6, 6))
    for ax, n in zip(axes.ravel(), shapes):
        ax.imshow(views[n]["views"][_aligned_view_index(int(labels[n]), V)], cmap="gray", vmin=0, vmax=255)
        ax.set_title(f"{n}: label {int(labels[n])}", fontsize=8)
    for ax in axes.ravel():
        ax.axis("off")
    fig.suptitle("aligned shapes (common view 0)")
    return _save(fig, out_dir, "aligned_grid.png")


@register("align.figures", fanout="once", writes_files=True)
def figures(views, features, costs, solution, *, shapes: list = ("001", "002", "003"),
            grid: list = ("001", "002", "003", "004", "005", "006", "007", "008", "009"),
            hog_views: list = (0, 4, 8), out_dir: str) -> dict:
    """Figures: HoG drawings of 3 views of 3 shapes, the D_ij heat map of the first two shapes, their best
    and worst view pairs, and a 3x3 grid of aligned shapes (falls back to the first shapes by name)."""
    names = list(solution["names"])
    labels = dict(zip(names, np.asarray(solution["labels"])))
    V = int(solution["n_views"])
    three = _pick(names, list(shapes), 3)
    a, b = three[0], three[1] if len(three) > 1 else three[0]
    made = [_figure_hog(views, features, three, list(hog_views), V, out_dir),
            _figure_dij(costs, a, b, V, out_dir),
            _figure_view_pairs(views, features, a, b, out_dir),
            _figure_grid(views, labels, _pick(names, list(grid), 9), V, out_dir)]
    return {"figures": made}


@register("align.contact_sheet", fanout="once", writes_files=True)
def contact_sheet(views, solution, *, columns: int = 10, out_dir: str) -> dict:
    """All shapes' aligned view 0 in one image (to check an alignment by eye)."""
    plt = _plt()
    names = list(solution["names"])
    labels = np.asarray(solution["labels"])
    V = int(solution["n_views"])
    rows = int(np.ceil(len(names) / columns))
    fig, axes = plt.subplots(rows, columns, figsize=(1.2 * columns, 1.3 * rows), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, n, l in zip(axes.ravel(), names, labels):
        ax.imshow(views[n]["views"][_aligned_view_index(int(l), V)], cmap="gray", vmin=0, vmax=255)
        ax.set_title(n, fontsize=6)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "all_aligned.png"), dpi=80)
    plt.close(fig)
    return {"figures": ["all_aligned.png"]}
