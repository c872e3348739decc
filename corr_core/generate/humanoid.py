"""Procedural articulated humanoid: a closed, left/right symmetric surface mesh posed with the same connectivity.

Frame of the rest pose: y up (feet at y ~ 0, head top at y ~ 1.76, units ~ metres), the body faces +z, the
person's LEFT side is +x (names "Left ..." are at x > 0). Rest pose: standing, arms 35 degrees below horizontal.

Construction: a skeleton of joints; the surface is the zero level set of a smooth union (polynomial smooth-min)
of round cones / ellipsoids. The x >= 0 half is meshed with ``skimage.measure.marching_cubes`` (its flat cap on
the midplane is cut off) and glued to its mirror image, so the mesh is exactly left/right symmetric in vertices
and connectivity; vertices are then relaxed tangentially and projected back onto the implicit surface (better
triangles; mirror pairs kept exact). Poses use linear blend skinning with weights diffused over the surface from a
nearest-bone labelling, so every pose has the same vertices and faces and vertex i matches vertex i
(near-isometric; stretch only near joints).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from corr_core.correspondence.landmarks import format_landmarks, write_landmarks
from corr_core.geometry.mesh_io import save_obj
from corr_core.geometry.primitives import largest_component, vertex_adjacency, vertex_normals

ARM_DROP_DEG = 35.0


def _unit(v) -> np.ndarray:
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


# ---------------------------------------------------------------------------------------------------------------
# implicit surface


def _round_cone(P: np.ndarray, a, b, ra: float, rb: float, squash_z: float = 1.0) -> np.ndarray:
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
    d = _round_cone(P, [0, 0.86, 0], J["waist"], 0.145, 0.125, squash_z=1.45)
    d = _smin(d, _round_cone(P, J["waist"], [0, 1.36, 0], 0.125, 0.155, squash_z=1.5), k)
    d = _smin(d, _round_cone(P, J["L_shoulder"] * [0.6, 1, 1], J["R_shoulder"] * [0.6, 1, 1], 0.07, 0.07,
                             squash_z=1.3), k)
    d = _smin(d, _round_cone(P, J["neck"] - [0, 0.05, 0], J["head"], 0.052, 0.05), k)
    d = _smin(d, _ellipsoid(P, J["head"] + [0, 0.01, 0], [0.082, 0.108, 0.098]), 0.02)
    d = _smin(d, _ellipsoid(P, J["head"] + [0, -0.015, 0.075], [0.022, 0.03, 0.03]), 0.015)  # nose
    for side in "LR":
        j = lambda name: J[f"{side}_{name}"]  # noqa: E731
        d = _smin(d, _round_cone(P, j("shoulder"), j("elbow"), 0.052, 0.04), k)
        d = _smin(d, _round_cone(P, j("elbow"), j("wrist"), 0.04, 0.03), 0.02)
        d = _smin(d, _round_cone(P, j("wrist"), j("fingertip"), 0.034, 0.024, squash_z=1.0), 0.02)
        d = _smin(d, _round_cone(P, j("hip"), j("knee"), 0.085, 0.055), k)
        d = _smin(d, _round_cone(P, j("knee"), j("ankle"), 0.052, 0.035), 0.02)
        d = _smin(d, _round_cone(P, j("ankle") + [0, -0.03, -0.03], j("toe"), 0.04, 0.03), 0.02)
    return d


def _sample_half_grid(h: float) -> tuple[np.ndarray, np.ndarray]:
    """SDF of the x >= 0 half body on a grid with x = -h/2, h/2, 3h/2, ...; returns vol (nx,ny,nz), origin (3,).

    The x = -h/2 column holds |f(h/2)|: outside everywhere, and where the body crosses the midplane the iso-surface
    crosses the x-edges exactly at x = 0, giving a flat cap there (removed later).
    """
    mx = int(np.ceil(0.95 / h))
    xs = h * (np.arange(0, mx + 1) + 0.5)
    ys = h * np.arange(int(np.floor(-0.06 / h)), int(np.ceil(1.86 / h)) + 1)
    zs = h * np.arange(int(np.floor(-0.22 / h)), int(np.ceil(0.30 / h)) + 1)
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    half = body_sdf(np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)).reshape(X.shape) + 1e-9  # no exact zeros
    vol = np.concatenate([np.abs(half[:1]), half], axis=0)
    return vol, np.array([-0.5 * h, ys[0], zs[0]])


def _mirror_half(V: np.ndarray, F: np.ndarray, mid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Glue a half mesh (V (n,3), F (m,3), open along the midplane vertices ``mid`` (n,) bool) to its mirror image.

    Vertices: the half's vertices, then mirror copies of the non-midplane ones; faces: the half's, then mirrored
    (orientation reversed). Returns the closed, exactly symmetric mesh.
    """
    off = np.flatnonzero(~mid)
    mirror_id = np.arange(len(V))
    mirror_id[off] = len(V) + np.arange(len(off))
    Vm = V[off] * [-1.0, 1.0, 1.0]
    return np.concatenate([V, Vm]), np.concatenate([F, mirror_id[F][:, ::-1]])


def _project_to_surface(P: np.ndarray, iters: int = 2, eps: float = 1e-5) -> np.ndarray:
    """Newton-project points P: (n,3) onto the zero set of ``body_sdf`` (forward-difference gradient)."""
    n = len(P)
    for _ in range(iters):
        vals = body_sdf(np.concatenate([P, P + [eps, 0, 0], P + [0, eps, 0], P + [0, 0, eps]])).reshape(4, n)
        f = vals[0]
        g = (vals[1:] - f).T / eps
        P = P - (f / np.maximum((g * g).sum(1), 1e-12))[:, None] * g
    return P


def mirror_pairs(V: np.ndarray, tol: float = 1e-5) -> np.ndarray | None:
    """(n,) index of each vertex's mirror image (x -> -x) in V: (n,3), or None if the set is not symmetric."""
    from scipy.spatial import cKDTree

    dist, pair = cKDTree(V).query(V * [-1.0, 1.0, 1.0])
    if dist.max() > tol or np.any(pair[pair] != np.arange(len(V))):
        return None
    return pair


def _relax(V: np.ndarray, F: np.ndarray, iters: int = 6, step: float = 0.5) -> np.ndarray:
    """Tangential uniform-Laplacian relaxation with re-projection onto the implicit surface.

    Marching cubes on the mirror-symmetric grid gives an exactly symmetric vertex set, but its triangulation is not
    exactly mirrored; averaging each vertex with its mirrored partner after every step keeps the set symmetric.
    """
    A = vertex_adjacency(F, len(V))
    deg = np.asarray(A.sum(1)).ravel()
    pair = mirror_pairs(V)
    for _ in range(iters):
        N = vertex_normals(V, F)
        L = (A @ V) / deg[:, None] - V
        L -= (L * N).sum(1, keepdims=True) * N
        V = _project_to_surface(V + step * L)
        if pair is not None:
            V = 0.5 * (V + V[pair] * [-1.0, 1.0, 1.0])
    return V


DEFAULT_GRID_STEP = 0.0225  # metres: about 4-5 thousand vertices


def make_humanoid_rest(grid_step: float = DEFAULT_GRID_STEP) -> tuple[np.ndarray, np.ndarray]:
    """The rest-pose surface mesh. Returns V: (n,3) float metres, F: (m,3) int, outward oriented, closed.

    Exactly left/right symmetric by construction: the x >= 0 half is meshed (marching cubes), its midplane cap is cut
    off and the half is glued to its mirror image; vertex positions and connectivity are mirror images.
    ``grid_step`` (metres) sets the resolution (0.0225 gives about 4-5 thousand vertices). Deterministic.
    """
    from skimage.measure import marching_cubes

    vol, origin = _sample_half_grid(grid_step)
    V, F, _, _ = marching_cubes(vol, level=0.0, spacing=(grid_step,) * 3, allow_degenerate=False)
    V = V.astype(np.float64) + origin  # marching_cubes works in float32
    mid = np.abs(V[:, 0]) < 1e-3 * grid_step
    V[mid, 0] = 0.0
    F = F.astype(np.int64)
    F = F[~mid[F].all(1)]  # drop the flat cap on the midplane
    V, F, _ = largest_component(V, F, by="vertices")
    V, F = _mirror_half(V, F, V[:, 0] == 0.0)
    V = _relax(V, F)
    if _signed_volume(V, F) < 0:
        F = F[:, ::-1].copy()
    return V, F


def _signed_volume(V: np.ndarray, F: np.ndarray) -> float:
    return float(np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6.0)


# ---------------------------------------------------------------------------------------------------------------
# skinning

# bone name -> (parent, pivot joint, list of segments (joint a, joint b) used for the nearest-bone labelling,
# radius used to normalise distances)
def _bones(J: dict[str, np.ndarray]) -> list[tuple[str, str | None, np.ndarray, list, float]]:
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


def _segment_distance(P: np.ndarray, a, b) -> np.ndarray:
    return _round_cone(P, a, b, 0.0, 0.0)


def skinning_weights(V: np.ndarray, F: np.ndarray, smooth_iters: int = 60) -> tuple[np.ndarray, list[str]]:
    """Smooth LBS weights. Returns W: (n, B) rows summing to 1 and the B bone names.

    Each vertex is first assigned to the bone with the smallest radius-normalised distance; the one-hot labels are
    then diffused along the surface (``smooth_iters`` lazy random-walk steps), which blends near the joints
    without leaking across gaps in space (e.g. between the legs); weights below 1e-3 are dropped.
    """
    J = skeleton()
    bones = _bones(J)
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
    k = _unit(axis)
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
        arm = _unit(j("elbow") - j("shoulder"))
        fore = _unit(j("wrist") - j("elbow"))
        R[f"{s}_upperarm"] = (_axis_angle(np.cross(arm, z), r(pose[f"{s}_arm_flex"]))
                              @ _axis_angle(np.cross(arm, y), r(pose[f"{s}_arm_raise"])))
        R[f"{s}_forearm"] = _axis_angle(np.cross(fore, z), r(pose[f"{s}_elbow"]))
        R[f"{s}_hand"] = _axis_angle(np.cross(fore, y), r(pose[f"{s}_wrist"]))
        thigh = _unit(j("knee") - j("hip"))
        shin = _unit(j("ankle") - j("knee"))
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
    bones = _bones(J)
    local = _local_rotations(pose, J)
    glob: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, parent, pivot, _, _ in bones:  # parents precede children in _bones
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


# ---------------------------------------------------------------------------------------------------------------
# bodies: different people (limb lengths, girth, proportions) with the same vertices and faces

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
    u = _unit(axis)
    return girth * np.eye(3) + (length - girth) * np.outer(u, u)


def _body_scales(body: dict[str, float], J: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-bone (3,3) linear part of the rest-body change, about the bone's pivot (bone names of ``_bones``)."""
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
    bones = _bones(J)
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


# ---------------------------------------------------------------------------------------------------------------
# landmarks

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
    arm = _unit(J["L_elbow"] - J["L_shoulder"])
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


def make_humanoid_dataset(n_poses: int = 6, seed: int = 0, vary_bodies: bool = False,
                          grid_step: float = DEFAULT_GRID_STEP):
    """Rest mesh, posed meshes and landmarks, in memory.

    vary_bodies: each posed mesh is also a different person (``random_body`` from
    ``np.random.default_rng([seed, 1])``, so the poses are those of ``vary_bodies=False``); the rest mesh stays
    the rest body. Same vertices and faces either way.
    grid_step: resolution of ``make_humanoid_rest`` (metres; the default gives 4691 vertices, 0.03 about 2,600).
    Returns: (V_rest (n,3), F (m,3), poses list of (n,3) arrays, pose parameters list of dicts,
    landmarks dict name -> vertex id, bodies list of dicts (all 1.0 without ``vary_bodies``)).
    """
    V, F = make_humanoid_rest(grid_step)
    W, _ = skinning_weights(V, F)
    rng = np.random.default_rng(seed)
    params = [random_pose(rng) for _ in range(n_poses)]
    body_rng = np.random.default_rng([seed, 1])
    bodies = [random_body(body_rng) if vary_bodies else neutral_body() for _ in range(n_poses)]
    posed = []
    for pose, body in zip(params, bodies):
        Vb, Jb = shape_body(V, W, body) if vary_bodies else (V, None)
        posed.append(pose_mesh(Vb, W, pose, Jb))
    return V, F, posed, params, landmark_vertices(V), bodies


# ---------------------------------------------------------------------------------------------------------------
# other connectivity (a target whose true map is known by construction)

REMESH_KINDS = ("subdivided", "decimated")


def subdivide_midpoint(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """1-to-4 midpoint subdivision: V (n,3), F (m,3) -> V' (n + E,3) (the n vertices first, same ids, then
    one per edge), F' (4m,3), same orientation."""
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    edges, inverse = np.unique(E, axis=0, return_inverse=True)
    mid = len(V) + inverse.reshape(3, len(F)).T                 # (m,3): midpoint of edge (0,1), (1,2), (2,0)
    a, b, c = F.T
    ab, bc, ca = mid.T
    F2 = np.concatenate([np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return np.concatenate([V, V[edges].mean(axis=1)]), F2.astype(np.int64)


def _decimate(V: np.ndarray, F: np.ndarray, fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Quadric edge-collapse decimation (open3d) to ``fraction`` of the faces; unused vertices removed."""
    from corr_core.open3d_loader import load_open3d

    o3d = load_open3d()
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32)))
    m = m.simplify_quadric_decimation(int(len(F) * fraction))
    m.remove_unreferenced_vertices()
    return np.asarray(m.vertices, np.float64), np.asarray(m.triangles, np.int64)


def remesh(V: np.ndarray, F: np.ndarray, kind: str, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The same surface with another triangulation and vertex order, and the true map onto it.

    kind "subdivided": midpoint subdivision (exact: vertex i stays a vertex); "decimated": quadric decimation to
    half the faces (truth: the nearest kept vertex to each original one, i.e. exact to within an edge). The new
    vertex ids are shuffled (``np.random.default_rng(seed)``) so that no method can rely on vertex order.
    Args: V (n,3), F (m,3). Returns V2 (n2,3), F2 (m2,3), truth (n,) int: vertex of V2 that vertex i becomes.
    """
    from scipy.spatial import cKDTree

    if kind == "subdivided":
        V2, F2 = subdivide_midpoint(V, F)
        truth = np.arange(len(V))
    elif kind == "decimated":
        V2, F2 = _decimate(V, F, 0.5)
        truth = cKDTree(V2).query(V)[1]
    else:
        raise ValueError(f"remesh kind must be one of {REMESH_KINDS}, got {kind!r}")
    order = np.random.default_rng(seed).permutation(len(V2))   # new id of old vertex j: rank[j]
    rank = np.empty_like(order)
    rank[order] = np.arange(len(V2))
    return V2[order], rank[F2], rank[truth].astype(np.int64)


# ---------------------------------------------------------------------------------------------------------------
# dataset


def write_humanoid_dataset(out_dir: str | os.PathLike, n_poses: int = 6, seed: int = 0, vary_bodies: bool = False,
                           remeshed: tuple[str, ...] | list[str] = (), grid_step: float = DEFAULT_GRID_STEP) -> dict:
    """Write the course layout: ``meshes/template/mesh000.obj`` (rest pose), ``meshes/test/meshNNN.obj``
    (NNN = 001..n_poses, random poses drawn from ``np.random.default_rng(seed)``), ``landmark_vids.txt`` and
    ``sparse_landmark_vids.txt`` (``vid,Name`` lines, 0-based). All meshes share faces; vertex i matches vertex i.

    vary_bodies: the test meshes are other people too (``make_humanoid_dataset``); same faces.
    remeshed: kinds (``REMESH_KINDS``); the k-th is written as ``meshes/test/mesh<n_poses+k>.obj``, pose k
    (1-based) re-triangulated by ``remesh`` (seed k), with its true map ``ground_truth/<mesh>.txt`` (one target
    vertex id per template vertex, a line each) and its landmarks ``landmarks/<mesh>.txt`` (``vid,Name``).
    grid_step: mesh resolution (``make_humanoid_dataset``); coarser is cheaper to process (tests).
    Returns (JSON-serialisable): {"out_dir", "template", "tests": [paths], "landmarks": {name: vid},
    "sparse_landmarks": {name: vid}, "n_vertices", "n_faces", "poses": [dict of joint angles in degrees],
    "bodies": [dict of body factors], "remeshed": {mesh: {"kind", "n_vertices"}}}.
    """
    out = Path(out_dir)
    (out / "meshes" / "template").mkdir(parents=True, exist_ok=True)
    (out / "meshes" / "test").mkdir(parents=True, exist_ok=True)
    V, F, posed, params, lms, bodies = make_humanoid_dataset(n_poses, seed, vary_bodies=vary_bodies,
                                                             grid_step=grid_step)
    if len(remeshed) > n_poses:
        raise ValueError(f"remeshed: {len(remeshed)} kinds but only {n_poses} poses to remesh")
    template = out / "meshes" / "template" / "mesh000.obj"
    save_obj(template, V, F)
    tests = []
    for i, Vp in enumerate(posed, start=1):
        path = out / "meshes" / "test" / f"mesh{i:03d}.obj"
        save_obj(path, Vp, F)
        tests.append(str(path))
    remeshed_info = {}
    for k, kind in enumerate(remeshed, start=1):
        name = f"mesh{n_poses + k:03d}"
        V2, F2, truth = remesh(posed[k - 1], F, kind, seed=k)
        save_obj(out / "meshes" / "test" / f"{name}.obj", V2, F2)
        for sub, text in (("ground_truth", "".join(f"{t}\n" for t in truth)),
                          ("landmarks", format_landmarks([truth[lms[n]] for n in LANDMARK_NAMES], LANDMARK_NAMES))):
            (out / sub).mkdir(exist_ok=True)
            (out / sub / f"{name}.txt").write_text(text)
        tests.append(str(out / "meshes" / "test" / f"{name}.obj"))
        remeshed_info[name] = {"kind": kind, "n_vertices": int(len(V2))}
    write_landmarks(out / "landmark_vids.txt", [lms[n] for n in LANDMARK_NAMES], LANDMARK_NAMES)
    sparse = {n: lms[n] for n in SPARSE_LANDMARK_NAMES}
    write_landmarks(out / "sparse_landmark_vids.txt", list(sparse.values()), list(sparse))
    return {"out_dir": str(out), "template": str(template), "tests": tests, "landmarks": lms,
            "sparse_landmarks": sparse, "n_vertices": int(len(V)), "n_faces": int(len(F)),
            "poses": [{k: float(v) for k, v in p.items()} for p in params], "bodies": bodies,
            "remeshed": remeshed_info}
