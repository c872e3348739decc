"""Posing: skinning weights over the surface, random joint angles, and linear blend skinning."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from corr_core.generate.humanoid.rig import rig_bones, skeleton, unit_vector
from corr_core.generate.humanoid.surface import round_cone
from corr_core.geometry.primitives import vertex_adjacency


def _segment_distance(P: np.ndarray, a, b) -> np.ndarray:
    return round_cone(P, a, b, 0.0, 0.0)


def skinning_weights(V: np.ndarray, F: np.ndarray, *, smooth_iters: int = 60) -> tuple[np.ndarray, list[str]]:
    """Smooth LBS weights. Returns W: (n, B) rows summing to 1 and the B bone names.

    Each vertex is first assigned to the bone with the smallest radius-normalised distance; the one-hot labels are
    then diffused along the surface (``smooth_iters`` lazy random-walk steps), which blends near the joints
    without leaking across gaps in space (e.g. between the legs); weights below 1e-3 are dropped.
    """
    J = skeleton()
    bones = rig_bones(J)
    q = np.stack([np.min([_segment_distance(V, a, b) for a, b in segs], axis=0) / r
                  for _, _, _, segs, r in bones], 1)
    W = np.zeros_like(q)
    W[np.arange(len(V)), np.argmin(q, 1)] = 1.0
    A = vertex_adjacency(F, len(V))
    P = sp.diags(1.0 / np.asarray(A.sum(1)).ravel()) @ A
    for _ in range(smooth_iters):
        W = 0.5 * W + 0.5 * (P @ W)
    W[W < 1e-3] = 0.0  # diffusion leaves tiny weights everywhere; drop them so bones far from a joint stay rigid
    return W / W.sum(1, keepdims=True), [b[0] for b in bones]


def _axis_angle(axis, angle: float) -> np.ndarray:
    """(3,3) rotation about unit ``axis`` by ``angle`` radians (Rodrigues)."""
    k = unit_vector(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def random_pose(rng: np.random.Generator) -> dict[str, float]:
    """Plausible random joint angles in degrees (torso twist/bend, neck, arm raise/flex, elbow, hip, knee)."""
    p = {"twist": rng.uniform(-30, 30), "bend": rng.uniform(-10, 20),
         "neck_turn": rng.uniform(-40, 40), "neck_nod": rng.uniform(-15, 20)}
    for s in "LR":
        p |= {f"{s}_arm_raise": rng.uniform(-30, 75), f"{s}_arm_flex": rng.uniform(-15, 60),
              f"{s}_elbow": rng.uniform(0, 100), f"{s}_wrist": rng.uniform(-30, 30),
              f"{s}_hip_flex": rng.uniform(-15, 45), f"{s}_hip_spread": rng.uniform(-5, 20),
              f"{s}_knee": rng.uniform(0, 80), f"{s}_ankle": rng.uniform(-15, 15)}
    return p


def _local_rotations(pose: dict[str, float], J: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-bone (3,3) rotations about the bone pivot, axes expressed in the rest frame."""
    r = np.deg2rad
    x, y, z = np.eye(3)
    R = {"pelvis": np.eye(3),
         "abdomen": _axis_angle(y, r(pose["twist"]) / 2) @ _axis_angle(x, r(pose["bend"]) / 2),
         "chest": _axis_angle(y, r(pose["twist"]) / 2) @ _axis_angle(x, r(pose["bend"]) / 2),
         "neck": _axis_angle(y, r(pose["neck_turn"]) / 2) @ _axis_angle(x, r(pose["neck_nod"]) / 2),
         "head": _axis_angle(y, r(pose["neck_turn"]) / 2) @ _axis_angle(x, r(pose["neck_nod"]) / 2)}
    for s, sx in (("L", 1.0), ("R", -1.0)):
        j = lambda name: J[f"{s}_{name}"]  # noqa: E731
        arm = unit_vector(j("elbow") - j("shoulder"))
        fore = unit_vector(j("wrist") - j("elbow"))
        R[f"{s}_upperarm"] = (_axis_angle(np.cross(arm, z), r(pose[f"{s}_arm_flex"]))
                              @ _axis_angle(np.cross(arm, y), r(pose[f"{s}_arm_raise"])))
        R[f"{s}_forearm"] = _axis_angle(np.cross(fore, z), r(pose[f"{s}_elbow"]))
        R[f"{s}_hand"] = _axis_angle(np.cross(fore, y), r(pose[f"{s}_wrist"]))
        thigh = unit_vector(j("knee") - j("hip"))
        shin = unit_vector(j("ankle") - j("knee"))
        R[f"{s}_thigh"] = (_axis_angle(np.cross(thigh, z), r(pose[f"{s}_hip_flex"]))
                           @ _axis_angle(np.cross(thigh, [sx, 0, 0]), r(pose[f"{s}_hip_spread"])))
        R[f"{s}_shin"] = _axis_angle(np.cross(shin, -z), r(pose[f"{s}_knee"]))
        R[f"{s}_foot"] = _axis_angle(x, r(pose[f"{s}_ankle"]))
    return R


def pose_mesh(V: np.ndarray, W: np.ndarray, pose: dict[str, float],
              J: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Linear blend skinning of rest vertices V: (n,3) with weights W: (n,B) -> posed vertices (n,3).

    J: the rest skeleton of V (default ``skeleton()``; a body from ``shape_body`` passes its own).
    Forward kinematics: the global transform of a bone is its parent's composed with a rotation about its pivot.
    """
    J = skeleton() if J is None else J
    bones = rig_bones(J)
    local = _local_rotations(pose, J)
    glob: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, parent, pivot, _, _ in bones:  # parents precede children in ``rig_bones``
        Rl = local[name]
        tl = pivot - Rl @ pivot
        if parent is None:
            glob[name] = (Rl, tl)
        else:
            Rp, tp = glob[parent]
            glob[name] = (Rp @ Rl, Rp @ tl + tp)
    Rs = np.stack([glob[b[0]][0] for b in bones])          # (B,3,3)
    ts = np.stack([glob[b[0]][1] for b in bones])          # (B,3)
    per_bone = np.einsum("bij,nj->nbi", Rs, V) + ts[None]  # (n,B,3)
    return np.einsum("nb,nbi->ni", W, per_bone)
