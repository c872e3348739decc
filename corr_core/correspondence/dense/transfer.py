"""Landmark transfer: template landmarks placed on the target through a dense map."""
from __future__ import annotations

import numpy as np


def transfer_landmarks(p2p: np.ndarray, landmark_vids) -> np.ndarray:
    """Target vertex of each template landmark.

    Args:
        p2p: (n_template,) int target vertex id of every template vertex (``dense_map`` output).
        landmark_vids: (L,) int template vertex ids (e.g. read from landmark_vids.txt of the template).
    Returns: (L,) int target vertex ids, same order (names carry over unchanged).
    """
    p2p = np.asarray(p2p, dtype=np.int64)
    vids = np.asarray(landmark_vids, dtype=np.int64)
    if vids.ndim != 1:
        raise ValueError(f"landmark ids must be a 1-D list, got shape {vids.shape}")
    bad = vids[(vids < 0) | (vids >= len(p2p))]
    if len(bad):
        raise ValueError(f"landmark ids {bad.tolist()} are outside the template's 0..{len(p2p) - 1} vertices")
    placed = p2p[vids]
    if (placed < 0).any():
        lost = vids[placed < 0].tolist()
        raise ValueError(f"template landmarks at vertices {lost} have no image: they are off the template's largest "
                         "connected component (a loose piece or an unused vertex); move them onto the main surface")
    return placed


def format_dense_map(vertex_map: np.ndarray, header: tuple[str, ...] | list[str] = ()) -> str:
    """The text of a dense-map file: ``#`` header lines, then one line per template vertex i holding its
    target vertex id (0-based; -1: no image, off the template's kept component). ``read_dense_map`` and
    ``numpy.loadtxt`` read it back."""
    vm = np.asarray(vertex_map, dtype=np.int64).reshape(-1)
    return "".join(f"# {h}\n" for h in header) + "".join(f"{v}\n" for v in vm.tolist())


def read_dense_map(path, n_template: int | None = None, n_target: int | None = None) -> np.ndarray:
    """(n_template,) int64 of a dense-map file (``format_dense_map``; ``#`` lines are comments).

    Raises ValueError naming the file and the line when a line is not an integer, an id is below -1 or not a
    vertex of the target (``n_target``), or the count is not ``n_template``."""
    ids, lines = [], []
    with open(path, encoding="utf-8") as fh:
        for line_no, raw in enumerate(fh, start=1):
            text = raw.strip()
            if not text or text.startswith("#"):
                continue
            try:
                ids.append(int(text))
            except ValueError:
                raise ValueError(f"{path}:{line_no}: expected a target vertex id (an integer, -1 for none), "
                                 f"got {text!r}") from None
            lines.append(line_no)
    out = np.asarray(ids, dtype=np.int64)
    bad = np.flatnonzero((out < -1) | ((out >= n_target) if n_target is not None else False))
    if len(bad):
        i = int(bad[0])
        raise ValueError(f"{path}:{lines[i]}: target vertex id {ids[i]} is not -1 or a vertex id 0.."
                         f"{'n-1' if n_target is None else n_target - 1}")
    if n_template is not None and len(out) != n_template:
        raise ValueError(f"{path}: holds {len(out)} ids, one per template vertex is {n_template}")
    return out
