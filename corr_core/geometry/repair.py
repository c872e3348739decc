"""Repair a triangle mesh on load without ever renumbering its vertices.

Published scans carry duplicated faces (also in the opposite orientation), faces repeating a vertex, zero-area
faces, unreferenced vertices, inconsistent face orientation, fins on non-manifold edges, stray pieces and holes.
``repair_mesh`` fixes what can be fixed by changing only the *faces*: vertex ``i`` stays vertex ``i``, so ground
truth such as "vertex i matches vertex i" and landmark vertex ids survive. Vertices that no face uses afterwards
are simply ignored (``normalize_mesh`` and the renderer use referenced vertices only).

Every finding is a ``RepairRecord``; ``as_dict()`` gives its stored, JSON-ready form::

    {"file": name, "kind": "duplicate_faces", "action": "dropped", "count": 2, "level": "repair",
     "message": "scan.obj: dropped 2 duplicate faces ..."}

``level`` is "repair" (the faces were changed or vertices are ignored), "warning" (a defect that remains and
may matter, e.g. non-manifold edges) or "note" (informational: boundary loops, components kept).
What cannot be made usable raises ``MeshError`` with the reason and the fix.
"""
from __future__ import annotations

import dataclasses
import functools
import logging
import os

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from corr_core.geometry.mesh_io import MeshError, check_mesh, counted, load_mesh
from corr_core.geometry.primitives import (edge_keys, face_areas, half_edges, unique_edges, vertex_components,
                                           without_fins)

log = logging.getLogger(__name__)

__all__ = ["RepairRecord", "repair_mesh", "load_repaired_mesh", "orient_faces", "warn_repairs", "repair_messages",
           "compact_mesh", "coincident_representatives"]


@dataclasses.dataclass(frozen=True)
class RepairRecord:
    """One finding of ``repair_mesh``: in ``file``, ``count`` of ``kind`` (e.g. "duplicate_faces") were
    ``action`` ("dropped", "flipped", "kept", "ignored"); ``level`` "repair", "warning" or "note" (module
    docstring); ``message`` the sentence for the log, naming the file."""
    file: str
    kind: str
    action: str
    count: int
    level: str
    message: str

    def as_dict(self) -> dict:
        """The record as stage results store it: {"file", "kind", "action", "count", "level", "message"}."""
        return dataclasses.asdict(self)


def _record(name: str, kind: str, action: str, count: int, level: str, message: str) -> RepairRecord:
    return RepairRecord(name, kind, action, int(count), level, f"{name}: {message}")


def _bbox_diagonal2(V: np.ndarray, F: np.ndarray) -> float:
    """Squared bounding-box diagonal of the vertices that F: (m,3) uses (length^2)."""
    used = V[np.unique(F)]
    return float(np.sum((used.max(axis=0) - used.min(axis=0)) ** 2))


def coincident_representatives(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """For every vertex, the lowest id among the vertices that F uses at exactly its position: (n,) int64.

    A surface cut along a seam (a texture seam, parts exported separately, a triangle soup) repeats the seam's
    vertices with new ids, so it falls apart into pieces or gains a boundary along the seam; ``F`` re-pointed
    through this (``rep[F]``) is the welded surface, with every vertex id unchanged (the copies are then used by
    no face). A vertex no face uses keeps its own id unless a used vertex sits at its position (then it is that
    vertex's copy). Exact coordinates only: copies written by a tool carry the same numbers.

    Args: V: (n,3) float; F: (m,3) int. Returns: rep (n,) int64, rep[i] <= i for used vertices, rep[rep] == rep.
    """
    V = np.asarray(V, dtype=np.float64)
    n = len(V)
    rep = np.arange(n, dtype=np.int64)
    _, group = np.unique(V, axis=0, return_inverse=True)
    group = group.ravel()
    if group.max(initial=-1) + 1 == n:                                  # no two vertices share a position
        return rep
    used = np.zeros(n, dtype=bool)
    used[np.asarray(F, dtype=np.int64).ravel()] = True
    lowest_used = np.full(group.max() + 1, n, dtype=np.int64)
    np.minimum.at(lowest_used, group[used], np.flatnonzero(used))
    has_used = lowest_used[group] < n
    rep[has_used] = lowest_used[group[has_used]]
    return rep


def _weld(V: np.ndarray, F: np.ndarray, name: str, records: list) -> np.ndarray:
    """F (m,3) re-pointed to ``coincident_representatives``, with a record when anything was merged."""
    rep = coincident_representatives(V, F)
    used = np.unique(F)
    merged = used[rep[used] != used]
    if not len(merged):
        return F
    records.append(_record(name, "coincident_vertices", "merged", len(merged), "repair",
                           f"{counted(len(merged), 'vertex', 'vertices')} at exactly the position of a lower-numbered "
                           f"one merged into it (first: vertex {int(merged[0])} into {int(rep[merged[0]])}): the "
                           "surface is welded along its seams; vertex ids unchanged, the copies are used by no face"))
    return rep[F]


def _drop_repeated_index(F: np.ndarray, file_ids: np.ndarray, name: str, records: list) -> np.ndarray:
    """Keep-mask (m,) bool of the faces with three distinct vertices. file_ids: (m,) face numbers in the file."""
    bad = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    if bad.any():
        records.append(_record(name, "degenerate_faces", "dropped", bad.sum(), "repair",
                               f"dropped {counted(bad.sum(), 'face')} that "
                               f"repeat{'s' if bad.sum() == 1 else ''} a vertex (first: face "
                               f"{int(file_ids[bad][0])})"))
    return ~bad


def _orientation_sign(F: np.ndarray) -> np.ndarray:
    """(m,) +1 / -1: whether each face's vertex order is an even or odd permutation of its sorted order."""
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    return np.sign((b - a) * (c - a) * (c - b))


def _drop_duplicates(F: np.ndarray, file_ids: np.ndarray, name: str, records: list) -> np.ndarray:
    """Keep-mask (m,) bool: the first face of every vertex triple; later copies (either orientation) go."""
    S = np.sort(F, axis=1)
    n = int(S.max()) + 1
    key = (S[:, 0] * n + S[:, 1]) * n + S[:, 2] if n < 2_000_000 else S  # n^3 < 2^63
    _, first, inverse = np.unique(key, axis=0 if key.ndim == 2 else None, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    keep = np.zeros(len(F), dtype=bool)
    keep[first] = True
    if not keep.all():
        dup = np.flatnonzero(~keep)
        opposite = int(np.sum(_orientation_sign(F[dup]) != _orientation_sign(F[first[inverse[dup]]])))
        records.append(_record(name, "duplicate_faces", "dropped", len(dup), "repair",
                               f"dropped {counted(len(dup), 'duplicate face')} "
                               f"({len(dup) - opposite} same orientation, "
                               f"{opposite} opposite orientation; first: face {int(file_ids[dup[0]])} repeats "
                               f"face {int(file_ids[first[inverse[dup[0]]]])})"))
    return keep


def _drop_zero_area(V: np.ndarray, F: np.ndarray, file_ids: np.ndarray, name: str, records: list,
                    *, area_tol: float = 1e-12) -> np.ndarray:
    """Keep-mask (m,) bool of the faces with area > area_tol * (bounding-box diagonal)^2."""
    tiny = area_tol * max(_bbox_diagonal2(V, F), np.finfo(float).tiny)
    bad = face_areas(V, F) <= tiny
    if bad.any():
        records.append(_record(name, "zero_area_faces", "dropped", bad.sum(), "repair",
                               f"dropped {counted(bad.sum(), 'zero-area face')} (area <= {area_tol:g} x bbox "
                               f"diagonal^2; first: face {int(file_ids[bad][0])})"))
    return ~bad


def _interior_edge_pairs(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The two faces of every manifold interior edge and whether they traverse it the same way.

    Returns fa, fb: (e,) int face ids; same_direction: (e,) bool (True = inconsistently oriented pair).
    """
    half = half_edges(F)
    face_of = np.repeat(np.arange(len(F)), 3)
    _, inverse, counts = np.unique(edge_keys(half), return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    interior = np.flatnonzero(counts[inverse] == 2)
    paired = interior[np.argsort(inverse[interior], kind="stable")]
    a, b = paired[0::2], paired[1::2]
    return face_of[a], face_of[b], half[a, 0] == half[b, 0]


def orient_faces(F: np.ndarray) -> tuple[np.ndarray, int, int]:
    """Orient the faces consistently within each edge-connected patch, keeping the majority orientation.

    Faces are joined across manifold edges (exactly two faces); a breadth-first walk from each patch's lowest
    face decides which faces to flip, and a patch whose walk would flip more than half its faces is flipped the
    other way, so a mostly well-oriented scan keeps its orientation. A flip reverses a face's vertex order (so a
    face stored reversed gets back its original row).

    Args:
        F: (m,3) int faces without duplicates.
    Returns:
        F2: (m,3) int oriented faces (same rows, same vertex sets); n_flipped: faces flipped;
        n_inconsistent: interior edges still traversed the same way by both faces (a non-orientable surface).
    """
    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    fa, fb, same = _interior_edge_pairs(F)
    if not same.any():
        return F.copy(), 0, 0
    root = m  # a virtual face joined to the first face of every patch, so one walk covers all patches
    n_patch, patch = connected_components(sp.coo_matrix((np.ones(len(fa)), (fa, fb)), shape=(m, m)),
                                          directed=False)
    starts = np.full(n_patch, m, dtype=np.int64)
    np.minimum.at(starts, patch, np.arange(m))
    rows = np.concatenate([fa, fb, np.full(n_patch, root)])
    cols = np.concatenate([fb, fa, starts])
    parity = np.concatenate([same, same, np.zeros(n_patch, dtype=bool)]).astype(np.int8) + 1  # 1 keep, 2 flip
    graph = sp.csr_matrix((parity, (rows, cols)), shape=(m + 1, m + 1))
    order, pred = breadth_first_order(graph, root, directed=True, return_predecessors=True)
    order = order[1:]
    step = np.asarray(graph[pred[order], order]).ravel() == 2
    flip = np.zeros(m + 1, dtype=bool)
    for node, parent, s in zip(order.tolist(), pred[order].tolist(), step.tolist()):
        flip[node] = flip[parent] ^ s
    flip = flip[:m]
    flipped_per_patch = np.bincount(patch, weights=flip, minlength=n_patch)
    invert = 2 * flipped_per_patch > np.bincount(patch, minlength=n_patch)
    flip ^= invert[patch]
    out = F.copy()
    out[flip] = out[flip][:, ::-1]
    _, _, still = _interior_edge_pairs(out)
    return out, int(flip.sum()), int(still.sum())


def _orient(F: np.ndarray, name: str, records: list) -> np.ndarray:
    F, n_flipped, n_inconsistent = orient_faces(F)
    if n_flipped:
        records.append(_record(name, "reoriented_faces", "flipped", n_flipped, "repair",
                               f"flipped {counted(n_flipped, 'face')} to a consistent orientation"))
    if n_inconsistent:
        records.append(_record(name, "non_orientable_edges", "kept", n_inconsistent, "warning",
                               f"{counted(n_inconsistent, 'edge')} cannot be oriented consistently (non-orientable "
                               "surface); orientation-dependent results may be unreliable"))
    return F


# A mesh is turned outward when its signed volume ratio is below -OUTWARD_MARGIN. `python
# bench/orientation_ratios.py` printed ratios 0.475 to 0.559 for the pipelines' generated meshes, 0.531 to 0.603
# for the course SCAPE poses and their remeshed copies, 0.404 to 0.725 for halves cut off by a plane (open pieces,
# outward faces); a flat sheet has a ratio near 0 either way and is left as it is (an open curved piece counts as
# facing its convex side). Any margin well inside (0, 0.4) separates them; 0.2 is the middle.
OUTWARD_MARGIN = 0.2


def signed_volume_ratio(V: np.ndarray, F: np.ndarray) -> float:
    """Signed volume of the faces F (m,3) int seen from the centroid of their vertices V (n,3) float, over the sum
    of its terms' absolute values: near +1 for a closed surface whose faces point outward, -1 inward, near 0 for
    a flat sheet (an open curved piece: + when its faces point to its convex side)."""
    F = np.asarray(F, dtype=np.int64)
    c = V[np.unique(F)].mean(axis=0)
    a, b, d = V[F[:, 0]] - c, V[F[:, 1]] - c, V[F[:, 2]] - c
    det = np.einsum("ij,ij->i", a, np.cross(b, d))
    total = float(np.abs(det).sum())
    return float(det.sum()) / total if total > 0 else 0.0


def orient_outward(V: np.ndarray, F: np.ndarray, *, margin: float = OUTWARD_MARGIN) -> tuple[np.ndarray, float]:
    """F (m,3) int with every face reversed when the surface clearly faces inward (``signed_volume_ratio`` below
    -``margin``), else F itself; and that ratio (before any flip). Orientation tells left from right (the
    correspondence methods' chirality), so a scan exported with inward normals would otherwise be matched to
    the template's mirror image."""
    ratio = signed_volume_ratio(V, F)
    return (np.ascontiguousarray(F[:, ::-1]) if ratio < -margin else F), ratio


def _outward(V: np.ndarray, F: np.ndarray, name: str, records: list) -> np.ndarray:
    F2, ratio = orient_outward(V, F)
    if F2 is not F:
        records.append(_record(name, "reoriented_outward", "flipped", len(F), "repair",
                               f"its faces pointed inward (signed volume ratio {ratio:.2f}): all "
                               f"{counted(len(F), 'face')} flipped to point outward (orientation tells left "
                               "from right)"))
    return F2


def _report_non_manifold(F: np.ndarray, name: str, records: list) -> None:
    E, count = unique_edges(F)
    bad = count > 2
    if bad.any():
        first = E[np.flatnonzero(bad)[0]]
        records.append(_record(name, "non_manifold_edges", "kept", bad.sum(), "warning",
                               f"{counted(bad.sum(), 'non-manifold edge')} shared by more than two faces "
                               f"remain{'s' if bad.sum() == 1 else ''} after removing duplicates "
                               f"(first: ({int(first[0])}, {int(first[1])}))"))


def _drop_fins(V: np.ndarray, F: np.ndarray, name: str, records: list) -> np.ndarray:
    """Keep the largest patch joined across edges two faces share (``primitives.without_fins``): faces hanging on a
    non-manifold edge (fins) are dropped and reported."""
    F_kept = without_fins(V, F)
    if F_kept is F:
        return F
    n_dropped = len(F) - len(F_kept)
    share = 1.0 - face_areas(V, F_kept).sum() / face_areas(V, F).sum()
    records.append(_record(name, "non_manifold_pieces", "dropped", n_dropped, "repair",
                           f"dropped {counted(n_dropped, 'face')} joined to the surface only along non-manifold edges "
                           f"(fins: {share:.2%} of the area; vertex ids unchanged, the vertices only they used are "
                           "ignored)"))
    return F_kept


def _components(V: np.ndarray, F: np.ndarray, keep_largest: bool, name: str, records: list) -> np.ndarray:
    _, labels = vertex_components(len(V), F)
    face_label = labels[F[:, 0]]
    present = np.unique(face_label)
    if len(present) < 2:
        return F
    area = np.bincount(face_label, weights=face_areas(V, F), minlength=labels.max() + 1)
    best = int(np.argmax(area))  # ties: the component with the lowest vertex id
    if not keep_largest:
        records.append(_record(name, "components", "kept", len(present), "note",
                               f"{len(present)} connected components (all kept)"))
        return F
    keep = face_label == best
    n_used, n_kept = len(np.unique(F)), len(np.unique(F[keep]))
    records.append(_record(name, "components", "dropped", len(present) - 1, "repair",
                           f"kept the largest of {len(present)} components: {n_kept:,} of {n_used:,} vertices; "
                           f"{counted(n_used - n_kept, 'vertex', 'vertices')} in "
                           f"{counted(len(present) - 1, 'small piece')} ignored "
                           f"({counted((~keep).sum(), 'face')}, {1 - area[best] / area.sum():.2%} of the area; vertex "
                           "ids unchanged)"))
    return F[keep]


def _report_unreferenced(n_vertices: int, F: np.ndarray, name: str, records: list) -> None:
    unused = np.setdiff1d(np.arange(n_vertices), np.unique(F))
    if len(unused):
        records.append(_record(name, "unreferenced_vertices", "ignored", len(unused), "repair",
                               f"{counted(len(unused), 'vertex', 'vertices')} used by no face "
                               f"{'is' if len(unused) == 1 else 'are'} ignored (first: vertex "
                               f"{int(unused[0])}); they take no part in normalization or rendering"))


def _report_boundary(F: np.ndarray, name: str, records: list) -> None:
    E, count = unique_edges(F)
    border = E[count == 1]
    if len(border) == 0:
        return
    ids, local = np.unique(border, return_inverse=True)
    local = local.reshape(-1, 2)
    A = sp.coo_matrix((np.ones(len(local)), (local[:, 0], local[:, 1])), shape=(len(ids), len(ids)))
    n_loops, labels = connected_components(A, directed=False)
    sizes = np.bincount(labels[local[:, 0]], minlength=n_loops)
    records.append(_record(name, "boundary", "kept", n_loops, "note",
                           f"{counted(len(border), 'boundary edge')} in {counted(n_loops, 'loop')} "
                           f"(open surface or holes, not "
                           f"filled; smallest loop {int(sizes.min())} edges, largest {int(sizes.max())})"))


def repair_mesh(V: np.ndarray, F: np.ndarray, name: str = "mesh", *, keep_largest_component: bool = False,
                orient: bool = True, outward: bool = False, weld: bool = False, area_tol: float = 1e-12
                ) -> tuple[np.ndarray, list[RepairRecord]]:
    """Repair the faces of a mesh; vertices and their ids are never changed.

    Steps, each reported when it finds something: weld seams (``weld``: faces re-pointed from a vertex to the
    lowest-numbered used vertex at exactly its position, ``coincident_representatives``); drop faces repeating a
    vertex; drop duplicate faces (same three vertices in either orientation; the first is kept); drop zero-area
    faces; orient faces consistently (``orient``); with ``keep_largest_component``, drop the faces joined to the
    surface only along non-manifold edges (fins, ``primitives.without_fins``); report remaining non-manifold edges
    and the vertices no face uses; keep only the largest connected component by area (``keep_largest_component``,
    for intrinsic methods: the record counts the vertices of the pieces left out) or report the components;
    report boundary loops.

    Args:
        V: (n,3) float vertex positions; F: (m,3) int faces; name: the file, for messages.
        keep_largest_component: drop every face outside the largest component and every fin (their vertices become
            unreferenced).
        orient: make the face orientation consistent.
        outward: after the components step, reverse every face of a surface that clearly faces inward
            (``orient_outward``; the correspondence meshes: orientation tells left from right).
        weld: merge coincident vertices first (the correspondence meshes: a seam would cut the surface, and the
            intrinsic methods would see a boundary or keep only one piece).
        area_tol: a face is zero-area when area <= area_tol * (bounding-box diagonal)^2.
    Returns:
        F2: (m2,3) int64 repaired faces (a subset of the rows of F, some with their vertex order reversed);
        records: list of ``RepairRecord``, in the order of the steps.
    Raises:
        MeshError: no faces, out-of-range indices, NaN/inf coordinates of a used vertex, or no valid face left.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    check_mesh(V, F, name=name)
    records: list[RepairRecord] = []
    file_ids = np.arange(len(F))
    faces_of_file = F
    if weld:
        F = _weld(V, F, name, records)
    for step in (_drop_repeated_index, _drop_duplicates, functools.partial(_drop_zero_area, V, area_tol=area_tol)):
        if len(F):
            keep = step(F, file_ids, name, records)
            F, file_ids = F[keep], file_ids[keep]
    if len(F) == 0:
        raise MeshError(f"{name}: no valid face left after removing degenerate and zero-area faces; "
                        "the file has no usable surface (export it again as a triangle mesh)")
    if orient:
        F = _orient(F, name, records)
    if keep_largest_component:
        F = _drop_fins(V, F, name, records)
    _report_non_manifold(F, name, records)
    _report_unreferenced(len(V), faces_of_file, name, records)  # by no face of the file (welded copies: see weld)
    F = _components(V, F, keep_largest_component, name, records)
    if outward:
        F = _outward(V, F, name, records)
    _report_boundary(F, name, records)
    return F, records


def load_repaired_mesh(path: str | os.PathLike, *, keep_largest_component: bool = False, orient: bool = True,
                       name: str | None = None) -> tuple[np.ndarray, np.ndarray, list[RepairRecord]]:
    """``load_mesh`` then ``repair_mesh``: (V (n,3) float64 in file order, F (m,3) int64 repaired, records).

    name: how messages name the file (default: the path).
    """
    path = os.fspath(path)
    V, F = load_mesh(path)
    F, records = repair_mesh(V, F, name or path, keep_largest_component=keep_largest_component, orient=orient)
    return V, F, records


def repair_messages(records: list[RepairRecord], levels: tuple = ("repair", "warning")) -> list[str]:
    """The messages of the records whose level is in ``levels``."""
    return [r.message for r in records if r.level in levels]


def warn_repairs(records: list[RepairRecord], levels: tuple = ("repair", "warning")) -> None:
    """One log message (``logging`` warning of this module's logger) per repair / remaining defect, one line each
    naming the file (``008.obj: dropped 4,780 duplicate faces ...``)."""
    for message in repair_messages(records, levels):
        log.warning(message)


def compact_mesh(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The referenced vertices only, for consumers that need no vertex ids (rendering, bounds).

    Args: V: (n,3) float; F: (m,3) int. Returns: V2: (k,3) = V[used] (used increasing), F2: (m,3) re-indexed.
    """
    used, F2 = np.unique(np.asarray(F), return_inverse=True)
    return np.asarray(V)[used], F2.reshape(-1, 3).astype(np.int64)
