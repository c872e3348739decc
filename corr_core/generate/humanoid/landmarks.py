"""The named landmarks: anatomical target points and the rest vertices nearest to them."""
from __future__ import annotations

import numpy as np

from corr_core.generate.humanoid.rig import skeleton, unit_vector


LANDMARK_NAMES = ["Left Toe", "Right Toe", "Left Knee", "Right Knee", "Left Hip", "Right Hip", "Left Hand",
                  "Right Hand", "Left Elbow", "Right Elbow", "Left Sholder", "Right Sholder", "Left Side",
                  "Right Side", "Left Chest", "Right Chest", "Left Back", "Right Back", "Vertex", "Belly"]
SPARSE_LANDMARK_NAMES = ["Left Toe", "Right Toe", "Left Hand", "Right Hand", "Vertex"]


def landmark_targets() -> dict[str, np.ndarray]:
    """Anatomical target points (3,) outside the rest surface; a landmark is the nearest surface vertex.

    Names follow the course data (including its spelling "Sholder"; "Vertex" = top of the head).
    """
    J = skeleton()
    T = {"Vertex": J["head"] + [0, 0.15, 0], "Belly": [0, 1.02, 0.16]}
    arm = unit_vector(J["L_elbow"] - J["L_shoulder"])
    for side, s in (("Left", 1.0), ("Right", -1.0)):
        m = np.array([s, 1.0, 1.0])
        k = side[0]
        T[f"{side} Toe"] = J[f"{k}_toe"] + [0, 0, 0.06]
        T[f"{side} Knee"] = J[f"{k}_knee"] + [0, 0, 0.08]
        T[f"{side} Hip"] = J[f"{k}_hip"] + np.array([0.12, 0.0, 0.0]) * m
        T[f"{side} Hand"] = J[f"{k}_fingertip"] + 0.05 * arm * m
        T[f"{side} Elbow"] = J[f"{k}_elbow"] + [0, 0, -0.07]
        T[f"{side} Sholder"] = J[f"{k}_shoulder"] + [0, 0.09, 0]
        T[f"{side} Side"] = np.array([0.17, 1.10, 0.0]) * m
        T[f"{side} Chest"] = np.array([0.09, 1.33, 0.14]) * m
        T[f"{side} Back"] = np.array([0.09, 1.33, -0.14]) * m
    return {name: np.asarray(T[name], float) for name in LANDMARK_NAMES}


def landmark_vertices(V: np.ndarray) -> dict[str, int]:
    """Landmark name -> index of the rest vertex nearest to its anatomical target (V: (n,3) rest pose)."""
    return {name: int(np.argmin(np.linalg.norm(V - p, axis=1))) for name, p in landmark_targets().items()}
