"""The humanoid's rig: rest-pose joint positions and the bone hierarchy that poses and bodies move."""
from __future__ import annotations

import numpy as np

ARM_DROP_DEG = 35.0


def unit_vector(v) -> np.ndarray:
    """``v`` scaled to length 1 (as floats)."""
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def skeleton() -> dict[str, np.ndarray]:
    """Rest-pose joint positions (3,) in metres, keyed by name; left side ("L_") at +x."""
    J = {
        "pelvis": np.array([0.0, 0.95, 0.0]),
        "waist": np.array([0.0, 1.08, 0.0]),
        "chest": np.array([0.0, 1.28, 0.0]),
        "neck": np.array([0.0, 1.50, 0.0]),
        "head": np.array([0.0, 1.645, 0.01]),
    }
    arm = np.array([np.cos(np.deg2rad(ARM_DROP_DEG)), -np.sin(np.deg2rad(ARM_DROP_DEG)), 0.0])
    for side, s in (("L", 1.0), ("R", -1.0)):
        m = np.array([s, 1.0, 1.0])
        J[f"{side}_shoulder"] = np.array([0.18, 1.44, 0.0]) * m
        J[f"{side}_elbow"] = J[f"{side}_shoulder"] + 0.28 * arm * m
        J[f"{side}_wrist"] = J[f"{side}_elbow"] + 0.25 * arm * m
        J[f"{side}_fingertip"] = J[f"{side}_wrist"] + 0.17 * arm * m
        J[f"{side}_hip"] = np.array([0.09, 0.92, 0.0]) * m
        J[f"{side}_knee"] = np.array([0.10, 0.50, 0.01]) * m
        J[f"{side}_ankle"] = np.array([0.11, 0.085, -0.02]) * m
        J[f"{side}_toe"] = np.array([0.12, 0.03, 0.15]) * m
    return J


def rig_bones(J: dict[str, np.ndarray]) -> list[tuple[str, str | None, np.ndarray, list, float]]:
    """The bones of skeleton ``J``, parents before children: (bone name, parent, pivot joint, list of segments
    (joint a, joint b) used for the nearest-bone labelling, radius used to normalise distances)."""
    bones = [
        ("pelvis", None, J["pelvis"], [([0, 0.84, 0], J["waist"])], 0.14),
        ("abdomen", "pelvis", J["waist"], [(J["waist"], J["chest"])], 0.13),
        ("chest", "abdomen", J["chest"], [(J["chest"], J["neck"] - [0, 0.06, 0]),
                                          (J["L_shoulder"] * [0.5, 1, 1], J["R_shoulder"] * [0.5, 1, 1])], 0.15),
        ("neck", "chest", J["neck"], [(J["neck"], J["neck"] + [0, 0.06, 0])], 0.05),
        ("head", "neck", J["neck"] + [0, 0.07, 0], [(J["head"] - [0, 0.05, 0], J["head"] + [0, 0.05, 0])], 0.10),
    ]
    for s in "LR":
        j = lambda name: J[f"{s}_{name}"]  # noqa: E731
        bones += [
            (f"{s}_upperarm", "chest", j("shoulder"), [(j("shoulder"), j("elbow"))], 0.05),
            (f"{s}_forearm", f"{s}_upperarm", j("elbow"), [(j("elbow"), j("wrist"))], 0.035),
            (f"{s}_hand", f"{s}_forearm", j("wrist"), [(j("wrist"), j("fingertip"))], 0.03),
            (f"{s}_thigh", "pelvis", j("hip"), [(j("hip"), j("knee"))], 0.075),
            (f"{s}_shin", f"{s}_thigh", j("knee"), [(j("knee"), j("ankle"))], 0.045),
            (f"{s}_foot", f"{s}_shin", j("ankle"), [(j("ankle"), j("toe"))], 0.035),
        ]
    return bones
