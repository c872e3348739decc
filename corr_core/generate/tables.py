"""Procedural tables of known rotational symmetry about +y, at known azimuths (deterministic by seed).

Kinds and their symmetry order k (the shape looks the same after turning it by 360/k degrees about +y):

- ``round``: a disc top on a central column and a disc foot, order 0 (= every angle; the discs have 48
  segments, so at any view count dividing 48 the views are identical);
- ``square``: a square top on four legs at the corners, order 4;
- ``rectangular``: a rectangular top (width / depth 1.4-2) on four legs, order 2.

Canonical frame as for the chairs (``corr_core.generate.chairs``): y up, bounding-box centre at the origin,
largest bounding-box side 1. ``write_table_collection`` rotates table i by its azimuth with ``Ry`` and may mix in
chairs (order 1) to check that symmetric shapes do not corrupt the alignment of the others.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from corr_core.generate.chairs import (box, canonical_chair, collection_azimuths, cylinder, merge_parts,
                                       write_ground_truth)
from corr_core.geometry.mesh_io import save_obj
from corr_core.geometry.primitives import rotate_about_y

__all__ = ["TABLE_KINDS", "SYMMETRY_ORDER", "make_table", "table_kind", "write_table_collection"]

TABLE_KINDS = ("round", "square", "rectangular")
SYMMETRY_ORDER = {"round": 0, "square": 4, "rectangular": 2, "chair": 1}


def make_table(rng: np.random.Generator, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """A random table of ``kind`` (one of TABLE_KINDS) in the canonical frame.

    Returns V: (n, 3) float, bbox-centred with largest bbox side 1; F: (m, 3) int.
    """
    if kind not in TABLE_KINDS:
        raise ValueError(f"table kind must be one of {TABLE_KINDS}, got {kind!r}")
    H = rng.uniform(0.55, 0.8)           # top height
    T = rng.uniform(0.03, 0.07)          # top thickness
    leg = rng.uniform(0.03, 0.06)        # leg width
    if kind == "round":
        R = rng.uniform(0.4, 0.6)
        parts = [cylinder([0, H - T, 0], [0, H, 0], R, segments=48),
                 cylinder([0, 0.02, 0], [0, H - T, 0], leg, segments=48, rings=2),
                 cylinder([0, 0, 0], [0, 0.02, 0], R * rng.uniform(0.4, 0.6), segments=48)]
    else:
        W = rng.uniform(0.5, 0.8)
        D = W if kind == "square" else W / rng.uniform(1.4, 2.0)
        inset = rng.uniform(0.0, 0.06)
        parts = [box([0, H - T / 2, 0], [W / 2, T / 2, D / 2], k=3)]
        for sx in (-1, 1):
            for sz in (-1, 1):
                x, z = sx * (W / 2 - inset - leg / 2), sz * (D / 2 - inset - leg / 2)
                parts.append(box([x, (H - T) / 2, z], [leg / 2, (H - T) / 2, leg / 2], k=2))
    V, F = merge_parts(parts)
    c = 0.5 * (V.min(0) + V.max(0))
    s = (V.max(0) - V.min(0)).max()
    return (V - c) / s, F


def table_kind(index: int) -> str:
    """Kind of table ``index`` (1-based): round, square, rectangular in turn."""
    return TABLE_KINDS[(index - 1) % len(TABLE_KINDS)]


def write_table_collection(out_dir: str | os.PathLike, *, n: int = 12, seed: int = 0, views: int = 16,
                           n_chairs: int = 0, continuous: bool = True) -> dict:
    """Write ``n`` tables (``001.obj``..) and then ``n_chairs`` chairs at known azimuths, plus
    ``ground_truth.csv`` (shape, azimuth_steps, azimuth_deg, kind, symmetry_order).

    Table i is ``make_table(np.random.default_rng([seed, 1, i]), table_kind(i))``; chair j is
    ``canonical_chair(seed, j)``; azimuths are ``collection_azimuths(n + n_chairs, seed, views, continuous)``.
    Returns {"out_dir", "names", "kinds", "symmetry_order", "azimuth_deg", "ground_truth"}.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    total = n + n_chairs
    steps, deg = collection_azimuths(total, seed, views, continuous)
    names, kinds = [], []
    for i in range(1, total + 1):
        if i <= n:
            kind = table_kind(i)
            V, F = make_table(np.random.default_rng([seed, 1, i]), kind)
        else:
            kind = "chair"
            V, F = canonical_chair(seed, i - n)
        name = f"{i:03d}"
        save_obj(out / f"{name}.obj", rotate_about_y(V, np.deg2rad(deg[i - 1])), F)
        names.append(name)
        kinds.append(kind)
    orders = [SYMMETRY_ORDER[k] for k in kinds]
    gt = out / "ground_truth.csv"
    write_ground_truth(gt, names, steps, deg, extra={"kind": kinds, "symmetry_order": orders},
                       whole_steps=not continuous)
    return {"out_dir": str(out), "names": names, "kinds": kinds, "symmetry_order": orders,
            "azimuth_deg": [float(v) for v in deg], "ground_truth": str(gt)}
