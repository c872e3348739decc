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
