"""The rest body as an implicit surface: a smooth union of round cones and ellipsoids around the rig."""
from __future__ import annotations

import numpy as np

from corr_core.generate.humanoid.rig import skeleton


def round_cone(P: np.ndarray, a, b, ra: float, rb: float, *, squash_z: float = 1.0) -> np.ndarray:
    """Approximate signed distance of points P: (n,3) to a capsule a->b with radius ra..rb (linear)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    ab = b - a
    t = np.clip(((P - a) @ ab) / (ab @ ab), 0.0, 1.0)
    d = P - (a + t[:, None] * ab)
    if squash_z != 1.0:
        d = d * np.array([1.0, 1.0, squash_z])
    return np.linalg.norm(d, axis=1) - (ra + (rb - ra) * t)


def _ellipsoid(P: np.ndarray, c, radii) -> np.ndarray:
    """Approximate signed distance of P: (n,3) to an axis-aligned ellipsoid (centre c, radii (3,))."""
    radii = np.asarray(radii, float)
    return (np.linalg.norm((P - np.asarray(c, float)) / radii, axis=1) - 1.0) * radii.min()


def _smin(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth minimum of two distance fields (blend radius k)."""
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b * (1 - h) + a * h - k * h * (1 - h)


def body_sdf(P: np.ndarray, J: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Approximate signed distance (negative inside, metres) of points P: (n,3) to the rest-pose body."""
    J = skeleton() if J is None else J
    k = 0.035
    d = round_cone(P, [0, 0.86, 0], J["waist"], 0.145, 0.125, squash_z=1.45)
    d = _smin(d, round_cone(P, J["waist"], [0, 1.36, 0], 0.125, 0.155, squash_z=1.5), k)
    d = _smin(d, round_cone(P, J["L_shoulder"] * [0.6, 1, 1], J["R_shoulder"] * [0.6, 1, 1], 0.07, 0.07,
                             squash_z=1.3), k)
    d = _smin(d, round_cone(P, J["neck"] - [0, 0.05, 0], J["head"], 0.052, 0.05), k)
    d = _smin(d, _ellipsoid(P, J["head"] + [0, 0.01, 0], [0.082, 0.108, 0.098]), 0.02)
    d = _smin(d, _ellipsoid(P, J["head"] + [0, -0.015, 0.075], [0.022, 0.03, 0.03]), 0.015)  # nose
    for side in "LR":
        j = lambda name: J[f"{side}_{name}"]  # noqa: E731
        d = _smin(d, round_cone(P, j("shoulder"), j("elbow"), 0.052, 0.04), k)
        d = _smin(d, round_cone(P, j("elbow"), j("wrist"), 0.04, 0.03), 0.02)
        d = _smin(d, round_cone(P, j("wrist"), j("fingertip"), 0.034, 0.024, squash_z=1.0), 0.02)
        d = _smin(d, round_cone(P, j("hip"), j("knee"), 0.085, 0.055), k)
        d = _smin(d, round_cone(P, j("knee"), j("ankle"), 0.052, 0.035), 0.02)
        d = _smin(d, round_cone(P, j("ankle") + [0, -0.03, -0.03], j("toe"), 0.04, 0.03), 0.02)
    return d
