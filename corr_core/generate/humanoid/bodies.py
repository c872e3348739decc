"""Other people: body proportions (lengths, girths, widths) applied per bone, with the same vertices and faces."""
from __future__ import annotations

import numpy as np

from corr_core.generate.humanoid.rig import rig_bones, skeleton, unit_vector


BODY_RANGES = {  # name -> (low, high) of a uniform draw; 1.0 = the rest body
    "height": (0.90, 1.10), "torso_length": (0.88, 1.15), "torso_girth": (0.85, 1.35),
    "shoulder_width": (0.88, 1.15), "hip_width": (0.88, 1.20), "arm_length": (0.85, 1.15),
    "arm_girth": (0.80, 1.35), "leg_length": (0.85, 1.15), "leg_girth": (0.80, 1.35), "head_size": (0.90, 1.10)}


def neutral_body() -> dict[str, float]:
    """The rest body's proportions (every factor 1.0): ``shape_body`` leaves the mesh unchanged."""
    return {name: 1.0 for name in BODY_RANGES}


def random_body(rng: np.random.Generator) -> dict[str, float]:
    """Random body proportions (dimensionless factors, ``BODY_RANGES``), drawn in the order of BODY_RANGES."""
    return {name: float(rng.uniform(lo, hi)) for name, (lo, hi) in BODY_RANGES.items()}


def _limb_scale(axis: np.ndarray, length: float, girth: float) -> np.ndarray:
    """(3,3) scaling by ``length`` along unit ``axis`` and ``girth`` across it."""
    u = unit_vector(axis)
    return girth * np.eye(3) + (length - girth) * np.outer(u, u)


def _body_scales(body: dict[str, float], J: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-bone (3,3) linear part of the rest-body change, about the bone's pivot (bone names of ``rig_bones``)."""
    b = body
    M = {"pelvis": np.diag([b["hip_width"], 1.0, b["torso_girth"]]),
         "abdomen": np.diag([b["torso_girth"], b["torso_length"], b["torso_girth"]]),
         "chest": np.diag([b["shoulder_width"], b["torso_length"], b["torso_girth"]]),
         "neck": np.eye(3), "head": b["head_size"] * np.eye(3)}
    for s in "LR":
        j = lambda name: J[f"{s}_{name}"]  # noqa: E731
        M[f"{s}_upperarm"] = _limb_scale(j("elbow") - j("shoulder"), b["arm_length"], b["arm_girth"])
        M[f"{s}_forearm"] = _limb_scale(j("wrist") - j("elbow"), b["arm_length"], b["arm_girth"])
        M[f"{s}_hand"] = _limb_scale(j("fingertip") - j("wrist"), b["arm_length"], b["arm_girth"])
        M[f"{s}_thigh"] = _limb_scale(j("knee") - j("hip"), b["leg_length"], b["leg_girth"])
        M[f"{s}_shin"] = _limb_scale(j("ankle") - j("knee"), b["leg_length"], b["leg_girth"])
        M[f"{s}_foot"] = np.eye(3)
    return M


def _joint_bone(J: dict[str, np.ndarray]) -> dict[str, str]:
    """Joint name -> the bone whose transform moves it (the parent bone of the bone it pivots, or its own
    bone for an end joint)."""
    owner = {"pelvis": "pelvis", "waist": "pelvis", "chest": "abdomen", "neck": "chest", "head": "head"}
    for s in "LR":
        owner |= {f"{s}_shoulder": "chest", f"{s}_elbow": f"{s}_upperarm", f"{s}_wrist": f"{s}_forearm",
                  f"{s}_fingertip": f"{s}_hand", f"{s}_hip": "pelvis", f"{s}_knee": f"{s}_thigh",
                  f"{s}_ankle": f"{s}_shin", f"{s}_toe": f"{s}_foot"}
    missing = set(J) - set(owner)
    if missing:
        raise ValueError(f"joints {sorted(missing)} have no owning bone")
    return owner


def shape_body(V: np.ndarray, W: np.ndarray, body: dict[str, float]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A different person from the rest mesh: same vertices (ids) and faces, other proportions.

    Each bone b gets the affine map x -> p_b' + M_b (x - p_b) (``_body_scales``: length along limbs, girth
    across them, torso and shoulder/hip widths, head size), where the new pivot p_b' is the parent's map applied
    to the rest pivot (forward kinematics, so joints stay attached); the maps are blended with the skinning
    weights W: (n,B), then the body stands on the rest body's floor and is scaled by ``height`` about the origin.
    Args: V: (n,3) rest vertices (metres); body: factors, keys of ``BODY_RANGES`` (missing ones are 1.0).
    Returns: V_body (n,3), J_body: its rest skeleton (for ``pose_mesh``).
    """
    unknown = set(body) - set(BODY_RANGES)
    if unknown:
        raise ValueError(f"unknown body factors {sorted(unknown)}; known: {sorted(BODY_RANGES)}")
    full = neutral_body() | {k: float(v) for k, v in body.items()}
    J = skeleton()
    bones = rig_bones(J)
    M = _body_scales(full, J)
    maps: dict[str, tuple[np.ndarray, np.ndarray]] = {}      # bone -> (M, t): x -> M x + t
    for name, parent, pivot, _, _ in bones:                   # parents precede children
        new_pivot = pivot if parent is None else maps[parent][0] @ pivot + maps[parent][1]
        maps[name] = (M[name], new_pivot - M[name] @ pivot)
    Ms = np.stack([maps[b[0]][0] for b in bones])
    ts = np.stack([maps[b[0]][1] for b in bones])
    Vb = np.einsum("nb,nbi->ni", W, np.einsum("bij,nj->nbi", Ms, V) + ts[None])
    owner = _joint_bone(J)
    Jb = {k: maps[owner[k]][0] @ p + maps[owner[k]][1] for k, p in J.items()}
    lift = np.array([0.0, V[:, 1].min() - Vb[:, 1].min(), 0.0])
    scale = full["height"]
    return scale * (Vb + lift), {k: scale * (p + lift) for k, p in Jb.items()}
