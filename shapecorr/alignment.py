"""Stage wiring for problem 1: joint azimuthal alignment of a shape collection.

views (per shape) -> hog (per shape) -> pairs (per tile of shape pairs: C_ij(theta)) -> solve (MRF)
-> evaluate (metrics) / export (aligned OBJs, views, alignment.csv, zips) / figures.
At scale (pipelines/scale.yaml): hog -> descriptor (per shape, rotation invariant) -> candidates (once: the
candidate graph) -> pairs on that graph only (``align.pair_costs_sparse`` with ``candidates:``) -> solve /
evaluate on the sparse costs.
The algorithms live in corr_core; these functions only load, call and store.
"""
from __future__ import annotations

import csv
import os
import shutil
import zipfile

import numpy as np

from corr_core import plotting
from corr_core.alignment import azimuth, candidates, graph_costs, measures, solvers
from corr_core.alignment.pair_costs import mirror_pair_costs, pair_costs_listed
from corr_core.alignment.pair_costs import pair_costs as compute_pair_costs
from corr_core.alignment.hog import hog_features
from corr_core.geometry.mesh_io import MESH_EXTENSIONS, normalize_mesh, save_obj
from corr_core.geometry.repair import compact_mesh, load_repaired_mesh, warn_repairs
from corr_core.alignment.render import render_views
from corr_core.alignment.views import load_view_stack

from stages.registry import register


def _input_kind(files: list[str]) -> str:
    exts = {os.path.splitext(f)[1].lower() for f in files}
    if len(files) == 1 and exts <= set(MESH_EXTENSIONS):
        return "mesh"
    if exts == {".png"}:
        return "views"
    raise ValueError(f"cannot tell whether {files[0]} ... is a mesh or a set of view images "
                     f"(extensions {sorted(exts)}); give one mesh ({'/'.join(MESH_EXTENSIONS)}) or NNN_V.png views per shape")


def _check_up(up: str) -> None:
    """ValueError naming the parameter 'up' unless it is one of the accepted axes (x, y, z)."""
    if up not in azimuth.UP_AXES:
        raise ValueError(f"parameter 'up' = {up!r}: the collection's up axis must be one of {sorted(azimuth.UP_AXES)}")


def _check_views(*, n_views: int, image_size: int, elevation_deg: float, center: str, up: str = "y") -> list[str]:
    """Config-time check of align.views params: ValueError for unusable values, warnings for meaningless ones."""
    _check_up(up)
    if n_views < 1:
        raise ValueError(f"parameter 'n_views' = {n_views}: a shape needs at least 1 view (the default is 16)")
    if image_size < 8:
        raise ValueError(f"parameter 'image_size' = {image_size}: views need at least 8x8 pixels")
    if n_views == 1:
        return ["n_views = 1: every rotation offset is 0, so the alignment metrics mean nothing"]
    return []


@register("align.views", group="alignment", fanout="item", validate=_check_views)
def views(files, *, n_views: int = 16, image_size: int = 120, elevation_deg: float = 20.0,
          center: str = "area", up: str = "y") -> dict:
    """Views of one shape: render a mesh (turned so its declared ``up`` axis x/y/z is +y, normalized: area
    centroid at the origin, unit radius) or load pre-rendered views.

    files: a list with one mesh path, or the shape's NNN_V.png paths in view order.
    Returns {"views": (V, S, S) uint8 grayscale (255 = white background), "kind": "mesh"|"views",
    "repairs": [dict] of the mesh repairs (``corr_core.geometry.repair.RepairRecord.as_dict``; [] for views)}.
    """
    files = [files] if isinstance(files, str) else list(files)
    kind = _input_kind(files)
    if kind == "mesh":
        V, F, repairs = load_repaired_mesh(files[0])  # faces repaired, vertex ids kept; records name the file
        warn_repairs(repairs)
        Vn, _, _ = normalize_mesh(azimuth.to_y_up(V, up), center=center, F=F)  # referenced vertices only
        images = render_views(*compact_mesh(Vn, F), n_views=n_views, image_size=image_size,
                              elevation_deg=elevation_deg)
    else:
        if len(files) != n_views:
            raise ValueError(f"{os.path.dirname(files[0])}: shape has {len(files)} views, expected n_views={n_views}")
        images = load_view_stack(files, size=image_size)
    if not np.all(np.isfinite(images)):
        raise ValueError(f"{files[0]}: views contain NaN values")
    return {"views": np.clip(np.rint(images * 255.0), 0, 255).astype(np.uint8), "kind": kind,
            "repairs": [r.as_dict() for r in repairs] if kind == "mesh" else []}


@register("align.hog", group="alignment", fanout="item")
def hog(views, *, method: str = "dollar") -> np.ndarray:
    """Per-shape feature: HoG of each view, (V, D) float32 (Dollar-compatible 15x15x36 at 120x120 by default)."""
    images = views["views"].astype(np.float32) / 255.0
    return hog_features(images, method=method).astype(np.float32)


@register("align.pair_costs", group="alignment", fanout="pair", mirror=mirror_pair_costs)
def pair_costs(A, B) -> np.ndarray:
    """C: (a, b, V) float32, C_ij(theta) = sum_v ||F_i[v] - F_j[v+theta]||^2 for a tile of shape pairs."""
    return compute_pair_costs(A, B)


@register("align.descriptor", group="alignment", fanout="item")
def descriptor(features, *, dim: int = candidates.DESCRIPTOR_DIM, seed: int = 0) -> dict:
    """Per-shape inputs of the candidate graph, from its view features (V, D): {"descriptor": (dim,) float32
    rotation-invariant descriptor (``candidates.rotation_invariant_descriptor``), "self_costs": (V,) float32
    C_ii(theta) (the shape's rotational symmetry)}."""
    F = np.asarray(features)
    return {"descriptor": candidates.rotation_invariant_descriptor(F, dim=dim, seed=seed),
            "self_costs": compute_pair_costs(F[None])[0, 0]}


def _check_candidates(*, graph: str, k: int, n_random: int, seed: int) -> None:
    """Config-time check of align.candidates params."""
    if graph not in ("candidates", "complete"):
        raise ValueError(f"parameter 'graph' = {graph!r}: use 'candidates' (k nearest + random pairs) or "
                         f"'complete' (every pair)")
    if k < 1 or n_random < 0:
        raise ValueError(f"parameters k = {k}, n_random = {n_random}: need k >= 1 and n_random >= 0")


@register("align.candidates", group="alignment", fanout="once", validate=_check_candidates)
def candidate_graph(descriptors, *, graph: str = "candidates", k: int = 10, n_random: int = 2,
                    seed: int = 0) -> dict:
    """The candidate graph of the pair stage: {"names": M shapes (sorted), "pairs": (P, 2) int64 indices,
    "kind": (P,) int8 (``candidates.PAIR_KINDS``), "self_costs": (M, V) float32, "graph", "k"}.
    graph "candidates": each shape's k nearest shapes by descriptor, n_random random partners per shape
    (seed), bridges until connected (``candidates.candidate_pairs``); "complete": every pair."""
    names = sorted(descriptors)
    X = np.stack([np.asarray(descriptors[n]["descriptor"]) for n in names])
    if graph == "complete":
        pairs, kind = candidates.complete_pairs(len(names))
    else:
        pairs, kind = candidates.candidate_pairs(X, k=k, n_random=n_random, seed=seed, self_pairs=False)
    return {"names": names, "pairs": pairs, "kind": kind, "graph": graph, "k": int(k),
            "self_costs": np.stack([np.asarray(descriptors[n]["self_costs"], np.float32) for n in names])}


@register("align.pair_costs_sparse", group="alignment", fanout="pair", mirror=mirror_pair_costs)
def pair_costs_sparse(A, B, *, pairs=None) -> np.ndarray:
    """C for listed pairs: (p, V) float32 for pairs (p, 2) local indices (row of A, row of B) of a candidate
    graph (``pair_costs_listed``), or the (a, b, V) tile of every pair when pairs is None."""
    return compute_pair_costs(A, B) if pairs is None else pair_costs_listed(A, B, pairs)


def _alignment_costs(costs: dict, graph: dict | None):
    """A pair stage's result as the solvers take it: the dense (N, N, V) matrix ({"names", "matrix"}) or, on a
    candidate graph ({"names", "pairs", "values"}), ``graph_costs.GraphCosts`` (with the graph's random sample
    and self costs when ``graph``, the candidates stage's result, is given)."""
    if "matrix" in costs:
        return np.asarray(costs["matrix"])
    return graph_costs.from_candidates(list(costs["names"]), costs["pairs"], costs["values"], graph)


@register("align.solve", group="alignment", fanout="once")
def solve(costs, graph=None, *, solver: str = "lh", sigma: float | str = "auto", sigma_scale: float = 1.0, seed: int = 0,
          knn: int = 0, symmetric: bool = True) -> dict:
    """Joint alignment: MRF over shapes with V labels (rotation offsets), W_ij = exp(-D_ij / sigma).

    costs: {"names": N names, "matrix": (N, N, V) C}, or the pairs of a candidate graph {"names", "pairs" (P, 2),
    "values" (P, V)} with graph: the candidates stage's result. solver: "lh" (Leordeanu & Hebert + climbing),
    "spectral" (angular synchronization), "ppm" (projected power). sigma: "auto" = median over pairs of
    min_theta C_ij, times sigma_scale. knn > 0 keeps only each shape's k nearest shapes in the graph.
    symmetric: detect each shape's rotational symmetry and keep symmetric shapes from steering the others.
    Returns {"names", "labels" (N,) int, "angles_deg" (N,) continuous degrees, "symmetry_order" (N,) int,
    "sigma", "energy", "solver", ...} (``corr_core.alignment.solvers.solve_alignment``).
    """
    out = solvers.solve_alignment(_alignment_costs(costs, graph), solver=solver, sigma=sigma,
                                  sigma_scale=sigma_scale, seed=seed, knn=knn, symmetric=symmetric)
    return {"names": list(costs["names"]), **out}


def _read_ground_truth(path) -> tuple[dict[str, int] | None, dict[str, float] | None, dict[str, int] | None]:
    """(steps, degrees, symmetry orders) {shape: value} of a ground_truth.csv (azimuth_steps, and the optional
    azimuth_deg and symmetry_order columns); None for a missing file or column."""
    if not path or not os.path.isfile(path):
        return None, None, None
    with open(path, encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))

    def column(key, cast):
        has = rows and all(r.get(key) not in (None, "") for r in rows)
        return {r["shape"]: cast(r[key]) for r in rows} if has else None
    return column("azimuth_steps", int), column("azimuth_deg", float), column("symmetry_order", int)


@register("align.evaluate", group="alignment", fanout="once")
def evaluate(costs, solution, ground_truth=None, other=None, graph=None, *, seeds: list = (0, 1, 2, 3, 4),
             shift_seed: int = 123, restarts: int = 20, compare_solvers: bool = True, icm_starts: int = 5) -> dict:
    """Metrics of an alignment run (all agreements are up to one global offset).

    - labels {name: view index} and angle_deg;
    - seed_stability: agreement of the labelings from several unary seeds with the first;
    - equivariance: shift each shape's views by known random offsets, solve again, fraction whose label moved
      by exactly that offset;
    - solver_quality: energies of the answer, ICM from random starts, best of random restarts, each solver
      (lh, spectral, ppm when ``compare_solvers``), a random labeling, and an upper bound; agreement_with peers;
    - ground_truth (generated data): fraction exact and within one view (per solver too), modulo each shape's
      symmetry, and the continuous mean_error_deg when the csv has azimuth_deg;
    - angles_deg {name: continuous degrees} and symmetry_order {name: k} (1 none, 0 every angle);
    - mode_agreement with another run's solution (e.g. meshes vs pre-rendered views) on common shapes.
    Re-solves use the solution's graph (``knn``); energies use the complete graph. On a candidate graph (costs
    and graph as for align.solve) everything is on that graph, plus pairs_computed / pairs_total.
    """
    steps, degrees, orders = _read_ground_truth(ground_truth)
    return measures.evaluate_alignment(_alignment_costs(costs, graph), solution, steps, other, seeds=seeds,
                                       shift_seed=shift_seed, restarts=restarts, compare_solvers=compare_solvers,
                                       truth_deg=degrees, truth_orders=orders, icm_starts=icm_starts)


def _write_alignment_csv(path: str, names: list[str], labels: np.ndarray, angles_deg: np.ndarray,
                         orders: np.ndarray) -> None:
    """alignment.csv: one row (shape, label, angle_deg (continuous), symmetry_order) per shape."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["shape", "label", "angle_deg", "symmetry_order"])
        for n, l, a, k in zip(names, labels, angles_deg, orders):
            w.writerow([n, int(l), f"{a:.2f}", int(k)])


ZIP_DATE_TIME = (1980, 1, 1, 0, 0, 0)   # the earliest a zip entry can carry: the same bytes from every run


def _zip_folder(folder: str) -> None:
    """<folder>.zip next to the folder (entries <folder name>/<file>, in name order), if the folder exists.

    Each entry gets a fixed date and mode instead of its file's: the archive of the same files is the same bytes
    from every run (with the files' own times, two runs' archives differed while their contents were equal)."""
    if os.path.isdir(folder):
        with zipfile.ZipFile(folder + ".zip", "w", zipfile.ZIP_DEFLATED) as z:
            for fn in sorted(os.listdir(folder)):
                entry = zipfile.ZipInfo(os.path.join(os.path.basename(folder), fn), date_time=ZIP_DATE_TIME)
                entry.compress_type = zipfile.ZIP_DEFLATED
                entry.external_attr = 0o644 << 16
                with open(os.path.join(folder, fn), "rb") as fh:
                    z.writestr(entry, fh.read())


def _check_export(*, center: str, up: str = "y") -> None:
    """Config-time check of align.export params (the up axis, as for align.views)."""
    _check_up(up)


@register("align.export", group="alignment", fanout="once", writes_files=True, validate=_check_export)
def export(shapes, solution, *, center: str = "area", up: str = "y", out_dir: str) -> dict:
    """Aligned outputs: alignment.csv (shape, label, continuous angle_deg, symmetry_order); for meshes the
    normalized OBJs turned to +y up (``up``) and by their continuous angle, and aligned_meshes.zip; for
    pre-rendered views each shape's nearest aligned view and aligned_views.zip."""
    names, labels, V = list(solution["names"]), np.asarray(solution["labels"]), int(solution["n_views"])
    angles = dict(zip(names, solvers.solution_angles_deg(solution)))
    _write_alignment_csv(os.path.join(out_dir, "alignment.csv"), names, labels, np.array(list(angles.values())),
                         np.asarray(solution.get("symmetry_order", np.ones(len(names), np.int64))))
    written = {"meshes": 0, "views": 0}
    mesh_dir, view_dir = os.path.join(out_dir, "aligned_meshes"), os.path.join(out_dir, "aligned_views")
    for n, l in zip(names, labels):
        files = shapes[n] if not isinstance(shapes[n], str) else [shapes[n]]
        if _input_kind(files) == "mesh":
            Vx, F, _ = load_repaired_mesh(files[0])  # the faces the views were rendered from
            Vn, _, _ = normalize_mesh(azimuth.to_y_up(Vx, up), center=center, F=F)
            os.makedirs(mesh_dir, exist_ok=True)
            save_obj(os.path.join(mesh_dir, f"{n}.obj"), azimuth.align_vertices_deg(Vn, angles[n]), F)
            written["meshes"] += 1
        else:
            os.makedirs(view_dir, exist_ok=True)
            shutil.copyfile(files[azimuth.aligned_view_index(int(l), V)], os.path.join(view_dir, f"{n}.png"))
            written["views"] += 1
    for folder in (mesh_dir, view_dir):
        _zip_folder(folder)
    return written


def _pick(names: list[str], wanted: list[str], k: int) -> list[str]:
    """The wanted shapes that exist, or the first k names when fewer than min(k, N) of them do."""
    chosen = [n for n in wanted if n in names]
    return chosen if len(chosen) >= min(k, len(names)) else sorted(names)[:k]


@register("align.figures", group="alignment", fanout="once", writes_files=True)
def figures(views, features, costs, solution, *, shapes: list = ("001", "002", "003"),
            grid: list = ("001", "002", "003", "004", "005", "006", "007", "008", "009"),
            hog_views: list = (0, 4, 8), out_dir: str) -> dict:
    """Figures: HoG drawings of 3 views of 3 shapes, the D_ij heat map of the first two shapes, their best
    and worst view pairs, and a 3x3 grid of aligned shapes (falls back to the first shapes by name)."""
    names = list(solution["names"])
    labels = dict(zip(names, np.asarray(solution["labels"])))
    three, nine = _pick(names, list(shapes), 3), _pick(names, list(grid), 9)
    a, b = three[0], three[1] if len(three) > 1 else three[0]
    stacks = {n: views[n]["views"] for n in dict.fromkeys(three + nine)}
    made = ["hog_drawings.png", "dij_heatmap.png", "view_pairs_best_worst.png", "aligned_grid.png"]
    path = {name: os.path.join(out_dir, name) for name in made}
    plotting.plot_hog_drawings(stacks, features, three, list(hog_views), path["hog_drawings.png"])
    C_ab = np.asarray(costs["matrix"])[costs["names"].index(a), costs["names"].index(b)]
    plotting.plot_pair_cost_heatmap(C_ab, a, b, path["dij_heatmap.png"])
    plotting.plot_view_pairs(stacks[a], stacks[b], features[a], features[b], a, b, path["view_pairs_best_worst.png"])
    plotting.plot_aligned_grid(stacks, labels, nine, path["aligned_grid.png"])
    return {"figures": made}


@register("align.contact_sheet", group="alignment", fanout="once", writes_files=True)
def contact_sheet(views, solution, *, columns: int = 10, out_dir: str) -> dict:
    """All shapes' aligned view 0 in one image (to check an alignment by eye)."""
    names = list(solution["names"])
    plotting.plot_contact_sheet({n: views[n]["views"] for n in names}, names, np.asarray(solution["labels"]),
                                os.path.join(out_dir, "all_aligned.png"), columns=columns)
    return {"figures": ["all_aligned.png"]}


