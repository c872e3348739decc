"""Azimuth labels (rotation offsets about +y in steps of 2*pi/V) and their comparison up to a global offset.

Convention (see corr_core.alignment.pair_costs): label x_i in 0..V-1 is shape i's rotation offset in steps relative to a
common frame; its angle is 2*pi*x_i/V radians; to align shape i rotate it by -x_i steps (-angle radians)
about +y. Labelings that differ by one global offset (x_i + o for all i) are the same alignment.
"""
from __future__ import annotations

import numpy as np

from corr_core.geometry.primitives import rotate_about_y

__all__ = ["labels_to_angles", "circular_distance", "agreement_up_to_offset", "relabel_by_offset",
           "aligned_view_index", "align_vertices", "align_vertices_deg", "UP_AXES", "to_y_up"]

# the rotation taking each declared up axis to +y (proper rotations: no mirroring)
UP_AXES = {"y": np.eye(3),
           "z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),    # about x by -90 deg: +z -> +y
           "x": np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])}    # about z by +90 deg: +x -> +y


def labels_to_angles(labels: np.ndarray, V: int) -> np.ndarray:
    """(n,) float radians in [0, 2*pi): 2*pi*labels/V for labels (n,) int (taken mod V)."""
    return 2.0 * np.pi * (np.asarray(labels, dtype=np.int64) % V) / V


def circular_distance(a: np.ndarray, b: np.ndarray, V: int) -> np.ndarray:
    """Elementwise circular distance in steps between labels a and b (broadcasting), in 0..V//2."""
    d = (np.asarray(a, dtype=np.int64) - np.asarray(b, dtype=np.int64)) % V
    return np.minimum(d, V - d)


def agreement_up_to_offset(labels_a: np.ndarray, labels_b: np.ndarray, V: int,
                           *, tolerance: int = 0) -> tuple[float, int]:
    """(fraction, best_offset): the largest fraction of items i with circular distance
    |labels_a[i] - (labels_b[i] + offset)| <= tolerance steps, over global offsets 0..V-1, and that offset
    (smallest one among ties). So labels_a ~= (labels_b + best_offset) % V.
    """
    a = np.asarray(labels_a, dtype=np.int64)
    b = np.asarray(labels_b, dtype=np.int64)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"labels must be two (n,) arrays of the same shape, got {a.shape} and {b.shape}")
    if a.size == 0:
        return 1.0, 0
    offsets = np.arange(V)[:, None]
    hits = circular_distance(a[None, :], b[None, :] + offsets, V) <= tolerance  # (V, n)
    frac = hits.mean(axis=1)
    best = int(np.argmax(frac))
    return float(frac[best]), best


def relabel_by_offset(labels: np.ndarray, offset: int, V: int) -> np.ndarray:
    """(labels + offset) % V: the same alignment expressed in a frame rotated by ``offset`` steps."""
    return (np.asarray(labels, dtype=np.int64) + int(offset)) % V


def aligned_view_index(label: int, V: int, *, k: int = 0) -> int:
    """Index of the original view that is view ``k`` of the common frame for a shape with label ``label``."""
    return int((k + label) % V)


def align_vertices(points: np.ndarray, label: int, V: int) -> np.ndarray:
    """points: (n,3) of a shape with label ``label`` rotated into the common frame (by -label steps about +y)."""
    return rotate_about_y(points, -2 * np.pi * int(label) / V)


def align_vertices_deg(points: np.ndarray, angle_deg: float) -> np.ndarray:
    """points: (n,3) of a shape at continuous azimuth ``angle_deg`` rotated into the common frame (by -angle
    about +y); equals ``align_vertices`` when angle_deg = label * 360 / V."""
    return rotate_about_y(points, -np.deg2rad(float(angle_deg)))


def to_y_up(points: np.ndarray, up: str = "y") -> np.ndarray:
    """points: (n,3) of a shape stored with ``up`` ("x", "y" or "z") as its up axis, rotated so that it is +y
    (the frame the views and azimuths use). ValueError naming the accepted axes otherwise."""
    if up not in UP_AXES:
        raise ValueError(f"up axis {up!r} is not one of {sorted(UP_AXES)} (the axis the collection stores as up)")
    points = np.asarray(points)
    return points if up == "y" else points @ UP_AXES[up].T
