"""Dense correspondence between two triangle meshes of any connectivity (numpy in, numpy out).

Steps (each callable on its own; see the modules):
  1. ``basis.mesh_basis``: per-mesh spectral basis, vertex areas, samples, geodesic solver (once per mesh).
  2. initial map: ``init.map_from_points`` (a few points given on both meshes, e.g. the 5 sparse landmarks) or
     ``init.map_automatic`` (nothing given on the target: extremities + assignment search, orientation-aware);
     both end with ZoomOut (``zoomout``, adjoint point maps) from the template samples to every target vertex.
  3. ``refine.upsample_spectral`` (every template vertex), then pointwise steps below ZoomOut's floor:
     ``refine.refine_extrinsic`` (patch-wise rigid ICP: robust patch fits, normal-compatible nearest vertices
     anywhere on the target, so twisted or slid regions come back) then ``refine.refine_spectral``
     (full-resolution ZoomOut with local candidates) then ``deform.refine_deform`` (as-rigid-as-possible
     registration of the template onto the target, read back as nearest vertices) by default;
     ``deform.refine_settle`` (the same registration without the pull toward the current images) and
     ``refine.refine_geodesic`` on request. The steps share ``nearest.nearest_compatible`` (the nearest target
     vertex whose normal agrees) and are named in one table, ``refine.REFINE_STEPS``.
  4. ``transfer.transfer_landmarks``; ``measures`` evaluates maps where ground truth exists.
``dense_map`` runs them in order. Convention: template = source; a map is (n_template,) int target vertex ids.
Ids: points given by the user are original vertex ids; maps between the steps are in the bases' local ids (the
largest connected component, ``basis``); ``map_to_original`` converts, and ``dense_map`` returns original ids.
"""
from __future__ import annotations

import numpy as np

from corr_core.correspondence.dense.basis import MeshBasis, map_to_original, mesh_basis
from corr_core.correspondence.dense.deform import refine_deform, refine_settle
from corr_core.correspondence.dense.init import automatic_hypotheses, map_automatic, map_from_points
from corr_core.correspondence.dense.refine import (DEFAULT_REFINE, BestMap, RefineStep, best_with_points,
                                                   map_distortion, points_agreement, refine_best, refine_extrinsic,
                                                   refine_geodesic, refine_map, refine_plan, refine_spectral,
                                                   second_opinion as refine_second_opinion,
                                                   surviving_after_step, surviving_hypotheses, upsample_spectral,
                                                   with_alternative)
from corr_core.correspondence.dense.transfer import format_dense_map, read_dense_map, transfer_landmarks

__all__ = ["MeshBasis", "mesh_basis", "map_to_original", "dense_map", "map_from_points", "map_automatic",
           "automatic_hypotheses", "upsample_spectral", "refine_extrinsic", "refine_geodesic", "refine_deform",
           "refine_settle",
           "refine_map", "refine_plan", "RefineStep", "refine_spectral", "refine_best", "BestMap",
           "surviving_hypotheses", "surviving_after_step", "best_with_points", "with_alternative", "map_distortion",
           "points_agreement", "refine_second_opinion", "DEFAULT_REFINE", "transfer_landmarks", "format_dense_map",
           "read_dense_map"]


def dense_map(V_template: np.ndarray, F_template: np.ndarray, V_target: np.ndarray, F_target: np.ndarray,
              landmarks_template=None, landmarks_target=None, *, k: int = 100, k_init: int = 40,
              refine: str | list | None = DEFAULT_REFINE, basis_template: MeshBasis | None = None,
              basis_target: MeshBasis | None = None, refine_options: dict | None = None,
              hypotheses: int | None = None, alternative: np.ndarray | None = None,
              second_opinion: bool = False) -> np.ndarray:
    """Dense map template -> target.

    Args:
        V_template: (n_s,3) float, F_template: (m_s,3) int; V_target: (n_t,3), F_target: (m_t,3) -- any vertex
            counts and triangulations; faces consistently oriented (outward normals on both).
        landmarks_template, landmarks_target: (L,) int corresponding vertex ids (L >= 3, e.g. the 5 sparse
            landmarks) or both None for the automatic map (no point needed on either mesh). Given points start
            the map and constrain its refinement (the registration holds them), and the map sends each template
            point to its target point (the first pair of a repeated template id).
        k: final spectral basis size (ZoomOut end); k_init: size of the initial functional map.
        refine: pointwise steps after ZoomOut, applied in the order named (``refine.refine_plan``):
            "extrinsic+spectral+deform" (default: ``refine_extrinsic``, ``refine_spectral``, then
            ``refine_deform``), a step followed by "?" kept only where it lowers the distortion, "extrinsic", "spectral", "deform", "settle" (``refine_settle``, on request),
            "geodesic" (``refine_geodesic``), any of them joined by "+", a list of names or ``RefineStep``s
            (``RefineStep("deform", {"stiffness": 0.02})``), or None.
        basis_template, basis_target: precomputed ``mesh_basis`` results (reuse them across pairs).
        refine_options: {step: kwargs} for the refinement functions (step: "extrinsic", "spectral", ...; a
            misspelt step or option is an error before any work).
        hypotheses: automatic mode only: how many ranked initial maps are refined (``init.automatic_hypotheses``;
            None: decided there, ``init.hypotheses_to_refine``: the best two, more when they are close); the
            least distorted refined map is kept (``refine.refine_best``), which resolves the 180-degree turn of
            a body whose front and back look alike.
        alternative: sparse mode only: (n_s,) int another map of the same pair in original ids (e.g. this
            function's automatic map). When it keeps the landmarks (80 % within 0.1 sqrt(area)), it and the map
            made from them both get the registration once more with the landmarks held, and the less distorted
            of the two is kept (``refine.with_alternative``): given points then do not make the map worse than
            the automatic one.
        second_opinion: automatic mode only: also make the map from the template's feature points and their
            images under the automatic map, refined with them held, and keep the less distorted of the two
            (``refine.second_opinion``): a lower error on every set measured for about 40 % more CPU, so off by
            default (docs/dense.md "A second opinion from the automatic map's own points").
    Returns:
        (n_s,) int64 target vertex id (original ids) of every template vertex; -1 for template vertices off the
        template's largest connected component (loose pieces, unused vertices: see ``basis``).
    """
    if (landmarks_template is None) != (landmarks_target is None):
        raise ValueError("give landmarks on both meshes (sparse mode) or on neither (automatic mode)")
    refine = refine_plan(refine, refine_options)                # a misspelt step or option fails here
    if alternative is not None and landmarks_template is None:
        raise ValueError("alternative: only with landmarks (the automatic mode compares its own hypotheses)")
    if alternative is not None:
        alternative = np.asarray(alternative, dtype=np.int64)
        if alternative.shape != (len(V_template),) or ((alternative < -1) | (alternative >= len(V_target))).any():
            raise ValueError(f"alternative must be a dense map of this pair: ({len(V_template)},) target vertex ids "
                             f"in 0..{len(V_target) - 1} (-1 off the template's kept component), got shape "
                             f"{alternative.shape}")
    S = basis_template if basis_template is not None else mesh_basis(V_template, F_template, k=k, name="template")
    T = basis_target if basis_target is not None else mesh_basis(V_target, F_target, k=k, name="target")
    if landmarks_template is None:
        starts = automatic_hypotheses(S, T, hypotheses, k_init=k_init, k_end=k)
    else:
        ls = np.asarray(landmarks_template, dtype=np.int64)
        lt = np.asarray(landmarks_target, dtype=np.int64)
        if ls.shape != lt.shape or ls.ndim != 1 or len(ls) < 3:
            raise ValueError(f"landmarks must be two (L,) id lists of equal length L >= 3, got {ls.shape} and "
                             f"{lt.shape}")
        starts = [map_from_points(S, T, ls, lt, k_init=k_init, k_end=k)]
    maps = [upsample_spectral(S, T, C, p2p_samples) for C, p2p_samples in starts]
    points = None if landmarks_template is None else (S.to_local(ls, what="template landmark"),
                                                      T.to_local(lt, what="target landmark"))
    best = refine_best(S, T, maps, refine, points=points)
    if second_opinion and points is None:
        best = refine_second_opinion(S, T, best, refine, k_init=k_init, k_end=k)
    if alternative is not None:
        best = with_alternative(S, T, best, alternative, points, refine=refine)
    return map_to_original(S, T, best.p2p)
