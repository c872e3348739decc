"""Dense correspondence between two triangle meshes of any connectivity (numpy in, numpy out).

Steps (each callable on its own; see the modules):
  1. ``basis.mesh_basis``: per-mesh spectral basis, vertex areas, samples, geodesic solver (once per mesh).
  2. initial map: ``init.map_from_points`` (a few points given on both meshes, e.g. the 5 sparse landmarks) or
     ``init.map_automatic`` (nothing given on the target: extremities + assignment search, orientation-aware);
     both end with ZoomOut (``zoomout``) on the samples.
  3. ``refine.upsample_spectral`` (every template vertex), then a pointwise step below ZoomOut's floor:
     ``refine.refine_extrinsic`` (patch-wise rigid ICP, the default) and/or ``refine.refine_geodesic``.
  4. ``transfer.transfer_landmarks``; ``measures`` evaluates maps where ground truth exists.
``dense_map`` runs them in order. Convention: template = source; a map is (n_template,) int target vertex ids.
"""
from __future__ import annotations

import numpy as np

from corr_core.correspondence.dense.basis import MeshBasis, mesh_basis
from corr_core.correspondence.dense.init import map_automatic, map_from_points
from corr_core.correspondence.dense.refine import refine_extrinsic, refine_geodesic, upsample_spectral
from corr_core.correspondence.dense.transfer import transfer_landmarks

__all__ = ["MeshBasis", "mesh_basis", "dense_map", "map_from_points", "map_automatic", "upsample_spectral",
           "refine_extrinsic", "refine_geodesic", "transfer_landmarks"]


def dense_map(V_template: np.ndarray, F_template: np.ndarray, V_target: np.ndarray, F_target: np.ndarray,
              landmarks_template=None, landmarks_target=None, *, k: int = 100, k_init: int = 40,
              refine: str | None = "extrinsic", basis_template: MeshBasis | None = None,
              basis_target: MeshBasis | None = None, refine_options: dict | None = None) -> np.ndarray:
    """Dense map template -> target.

    Args:
        V_template: (n_s,3) float, F_template: (m_s,3) int; V_target: (n_t,3), F_target: (m_t,3) -- any vertex
            counts and triangulations; faces consistently oriented (outward normals on both).
        landmarks_template, landmarks_target: (L,) int corresponding vertex ids (L >= 3, e.g. the 5 sparse
            landmarks) or both None for the automatic map (no point needed on either mesh).
        k: final spectral basis size (ZoomOut end); k_init: size of the initial functional map.
        refine: pointwise step after ZoomOut: "extrinsic" (``refine_extrinsic``), "geodesic"
            (``refine_geodesic``), "geodesic+extrinsic" (both, in that order) or None.
        basis_template, basis_target: precomputed ``mesh_basis`` results (reuse them across pairs).
        refine_options: {"geodesic": kwargs, "extrinsic": kwargs} for the refinement functions.
    Returns:
        (n_s,) int64 target vertex id of every template vertex.
    """
    if (landmarks_template is None) != (landmarks_target is None):
        raise ValueError("give landmarks on both meshes (sparse mode) or on neither (automatic mode)")
    S = basis_template if basis_template is not None else mesh_basis(V_template, F_template, k=k, name="template")
    T = basis_target if basis_target is not None else mesh_basis(V_target, F_target, k=k, name="target")
    if landmarks_template is None:
        C, p2p_samples = map_automatic(S, T, k_init=k_init, k_end=k)
    else:
        ls = np.asarray(landmarks_template, dtype=np.int64)
        lt = np.asarray(landmarks_target, dtype=np.int64)
        if ls.shape != lt.shape or ls.ndim != 1 or len(ls) < 3:
            raise ValueError(f"landmarks must be two (L,) id lists of equal length L >= 3, got {ls.shape} and "
                             f"{lt.shape}")
        C, p2p_samples = map_from_points(S, T, ls, lt, k_init=k_init, k_end=k)
    steps = {None: (), "extrinsic": ("extrinsic",), "geodesic": ("geodesic",),
             "geodesic+extrinsic": ("geodesic", "extrinsic")}
    if refine not in steps:
        raise ValueError(f"refine must be one of {list(steps)}, got {refine!r}")
    options = refine_options or {}
    p2p = upsample_spectral(S, T, C, p2p_samples)
    for step in steps[refine]:
        fn = refine_geodesic if step == "geodesic" else refine_extrinsic
        p2p = fn(S, T, p2p, **options.get(step, {}))
    return p2p
