"""The composed landmark matchers from a template mesh to a test mesh, on the per-mesh inputs of
``corr_core.correspondence.mesh_features``.

Each matcher returns {"all": (L,) int, "sparse": (k,) int}: for every template landmark the predicted test
landmark, with all L landmarks and within the sparse subset (positions ``sparse``: (k,) int into the L
landmarks; the sparse prediction indexes the sparse subset).

- ``match_descriptors``: descriptor distance (HKS, WKS or both) + Hungarian assignment;
- ``match_geodesic_mrf``: geodesic-consistency MRF (Leordeanu & Hebert), optionally with the orientation
  (chirality) test that resolves left/right swaps;
- ``match_mobius``: Möbius voting on the flattenings from triplets of sparse landmarks, extended to all
  landmarks by the consensus maps, plus a dense map from the best map and its geodesic errors.
"""
from __future__ import annotations

import numpy as np

from corr_core.correspondence import landmark_mrf, mobius, orientation
from corr_core.correspondence.descriptors import descriptor_distance
from corr_core.correspondence.matching import hungarian_match
from corr_core.correspondence.measures import geodesic_errors, numbering_problem
from corr_core.geometry.midedge import vertex_to_edge
from corr_core.geometry.sampling import farthest_point_samples

__all__ = ["descriptor_matrix", "match_descriptors", "match_geodesic_mrf", "mobius_inputs", "match_mobius",
           "dense_map_errors"]


def descriptor_matrix(signatures: dict, kind: str) -> np.ndarray:
    """(L, d) descriptor rows of kind "hks", "wks" or "hks+wks" (concatenated) from {"hks", "wks"}."""
    if kind == "hks":
        return signatures["hks"]
    if kind == "wks":
        return signatures["wks"]
    if kind == "hks+wks":
        return np.concatenate([signatures["hks"], signatures["wks"]], axis=1)
    raise ValueError(f"descriptor must be hks, wks or hks+wks, got {kind!r}")


def match_descriptors(template: dict, target: dict, sparse: np.ndarray, descriptor: str = "hks+wks",
                      metric: str = "relative_l1") -> dict:
    """Descriptor distance (``descriptor_distance`` with ``metric``) + Hungarian assignment, with all
    landmarks and within the sparse ones. template, target: ``spectral_features`` dicts."""
    cost = descriptor_distance(descriptor_matrix(template, descriptor), descriptor_matrix(target, descriptor),
                               metric=metric)
    return {"all": hungarian_match(cost), "sparse": hungarian_match(cost[np.ix_(sparse, sparse)])}


def match_geodesic_mrf(template: dict, target: dict, sparse: np.ndarray, *, sigma: float = 0.05,
                       orientation_test: bool = False) -> dict:
    """Pairwise geodesic-consistency MRF, w = exp(-(d(ia,ja) - d(ib,jb))^2 / (2 sigma)), solved by Leordeanu &
    Hebert, with all landmarks and within the sparse ones; ``orientation_test`` adds the chirality test.
    template, target: ``geodesic_features`` dicts ("D" normalized geodesics, "chirality")."""
    out = {}
    for key, idx in (("all", np.arange(len(template["D"]))), ("sparse", sparse)):
        dT, dS = template["D"][np.ix_(idx, idx)], target["D"][np.ix_(idx, idx)]
        if orientation_test:
            cT = template["chirality"][np.ix_(idx, idx, idx)]
            cS = target["chirality"][np.ix_(idx, idx, idx)]
            out[key] = orientation.match_landmarks_oriented(dT, dS, cT, cS, sigma=sigma)
        else:
            out[key] = landmark_mrf.match_landmarks_mrf(dT, dS, sigma=sigma)
    return out


def _complex(flat: dict) -> np.ndarray:
    return flat["Z"][:, 0] + 1j * flat["Z"][:, 1]


def mobius_inputs(flat: dict, area: float, sparse: np.ndarray, metric: str = "surface") -> dict:
    """Flattened samples and sparse landmarks of one mesh for ``mobius.mobius_vote_landmarks``.

    flat: a ``flattening_features`` dict; area: the mesh's surface area. With metric "surface" the local scales
    are in units of the sample spacing sqrt(area / n_samples). Returns {"Z": (E,) complex, "samples": (S,)
    complex, "landmarks": (L,) complex, "sparse": (k,) complex, "lam_samples", "lam_sparse": (S,), (k,) or None}.
    """
    Z = _complex(flat)
    S, L = flat["sample_eids"], flat["landmark_eids"]
    h = np.sqrt(area / len(S))
    surface = metric == "surface"
    return {"Z": Z, "samples": Z[S], "landmarks": Z[L], "sparse": Z[L[sparse]],
            "lam_samples": flat["lam"][S] * h if surface else None,
            "lam_sparse": flat["lam"][L[sparse]] * h if surface else None}


def _measured_vertices(template_V: np.ndarray, template_flat: dict, target_flat: dict, n_points: int) -> np.ndarray:
    """(n_points,) int farthest-point template vertices among those on both flattened surfaces."""
    on_both = np.intersect1d(np.unique(template_flat["edges"]), np.unique(target_flat["edges"]))
    if len(on_both) == len(template_V):
        return farthest_point_samples(template_V, n_points)
    return on_both[farthest_point_samples(np.asarray(template_V)[on_both], min(n_points, len(on_both)))]


def dense_map_errors(best_map: dict, template_flat: dict, target_flat: dict, template_V: np.ndarray,
                     target_V: np.ndarray, target_F: np.ndarray, n_points: int, metric: str = "plane") -> np.ndarray:
    """Geodesic errors / sqrt(area) (n_points,) of the dense map of one Möbius map, measured on ``n_points``
    farthest-point template vertices with the truth "vertex i <-> vertex i" (same connectivity required).

    Only vertices on both flattened surfaces (the kept components, see ``flattening_features``) are measured;
    the predicted images are always target vertices of the target's kept component.
    """
    src_vertices = _measured_vertices(template_V, template_flat, target_flat, n_points)
    src_eids = np.array([vertex_to_edge(int(v), template_flat["edges"]) for v in src_vertices])
    nn = mobius.dense_map(best_map, _complex(template_flat)[src_eids], _complex(target_flat), metric=metric)
    return geodesic_errors(target_V, target_F, target_flat["edges"][nn, 0], src_vertices)


def dense_vertex_map(best_map: dict, Z_template: np.ndarray, Z_target: np.ndarray, template_flat: dict,
                     target_flat: dict, n_template: int, metric: str = "plane") -> np.ndarray:
    """The dense map of one Möbius map for every template vertex: each vertex goes through its first edge
    midpoint to the nearest target midpoint, then to that edge's first vertex.

    Z_template, Z_target: (E,) complex flattened midpoints; *_flat: ``flattening_features`` dicts. Returns
    (n_template,) int target vertex ids; -1 for template vertices on no flattened edge (off the kept component,
    or used by no face).
    """
    on_surface = np.unique(template_flat["edges"])
    nn = mobius.dense_map(best_map, Z_template[vertex_to_edge(on_surface, template_flat["edges"])], Z_target,
                          metric=metric)
    out = np.full(int(n_template), -1, np.int64)
    out[on_surface] = target_flat["edges"][nn, 0]
    return out


def match_mobius(template_flat: dict, target_flat: dict, template_mesh: dict, target_mesh: dict,
                 sparse: np.ndarray, *, K: float = 0.5, metric: str = "surface", K_scale: float = 0.7,
                 power: float = 4.0, top: int = 100, dense_points: int = 200) -> dict:
    """Möbius voting from triplets of sparse landmarks, extended to all landmarks by the consensus maps (the
    maps that agree with the vote; the best maps when none does), and a dense map from the best map.

    template_flat, target_flat: ``flattening_features`` dicts; template_mesh, target_mesh: {"V", "F", "area"}.
    K: deformation-error threshold; with metric "surface" in units of the sample spacing sqrt(area /
    n_samples) (docs/mobius_notes.md), with "plane" in canonical-frame units (the paper).
    Returns {"sparse": (k,), "all": (L,), "best_score": float, "vertex_map": (n_template,) int target vertex of
    each template vertex under the best map (-1 off the kept component, see ``dense_vertex_map``),
    "dense_errors": (dense_points,) geodesic error / sqrt(area)}. The dense errors need the same vertex count and
    triangles as the template; otherwise they are left out and "dense_skipped" (str) says why.
    """
    s = mobius_inputs(template_flat, template_mesh["area"], sparse, metric)
    t = mobius_inputs(target_flat, target_mesh["area"], sparse, metric)
    surface = metric == "surface"
    res = mobius.mobius_vote_landmarks(s["samples"], t["samples"], s["sparse"], t["sparse"], K=K, metric=metric,
                                       lam_samples=(s["lam_samples"], t["lam_samples"]) if surface else None,
                                       lam_landmarks=(s["lam_sparse"], t["lam_sparse"]) if surface else None,
                                       power=power, K_scale=K_scale if surface else None)
    maps = res["consensus_maps"] or res["best_maps"]
    ext_metric = "plane" if surface else metric
    out = {"sparse": np.asarray(res["pred"]),
           "all": np.asarray(mobius.extend_landmarks(maps, s["landmarks"], t["landmarks"], top=top,
                                                     metric=ext_metric)),
           "best_score": float(res["best_maps"][0]["score"]),
           "vertex_map": dense_vertex_map(maps[0], s["Z"], t["Z"], template_flat, target_flat,
                                          len(template_mesh["V"]), ext_metric)}
    Vs, Fs, Vt, Ft = template_mesh["V"], template_mesh["F"], target_mesh["V"], target_mesh["F"]
    problem = numbering_problem(Fs, Ft, len(Vs), len(Vt))
    if problem:
        out["dense_skipped"] = (f"{problem} (the same triangles are required): no vertex i <-> vertex i ground "
                                "truth, dense-map errors skipped")
    elif dense_points > 0:
        out["dense_errors"] = dense_map_errors(maps[0], template_flat, target_flat, Vs, Vt, Ft, dense_points,
                                               ext_metric)
    return out
