"""Per-mesh inputs of the landmark matchers (``corr_core.correspondence.matchers``), computed once per mesh.

- ``spectral_features``: HKS and WKS at the landmarks (descriptor matching);
- ``geodesic_features``: diameter-normalized landmark geodesics and landmark chirality (geodesic MRF);
- ``flattening_features``: the mid-edge flattening, its local scale and surface samples (Möbius voting).

Meshes are V: (n,3) float, F: (m,3) int; landmarks are (L,) int vertex ids. Every computation runs on the largest
connected component of the referenced vertices (``corr_core.geometry.intrinsic.IntrinsicMesh``) and reports in the
original vertex ids; a landmark off that component raises ``OutsideComponentError`` naming it.
"""
from __future__ import annotations

import numpy as np

from corr_core.correspondence import descriptors
from corr_core.correspondence.orientation import landmark_chirality
from corr_core.geometry import laplacian, midedge
from corr_core.geometry.geodesic import GeodesicSolver
from corr_core.geometry.intrinsic import IntrinsicMesh
from corr_core.geometry.sampling import farthest_point_samples

__all__ = ["spectral_features", "geodesic_features", "flattening_features"]


def spectral_features(V: np.ndarray, F: np.ndarray, landmark_vids: np.ndarray, *, k: int = 100, n_times: int = 16,
                      n_energies: int = 100, wks_variance: float = 6.0) -> dict:
    """HKS and WKS at the landmark vertices from the first k Laplace-Beltrami eigenpairs.

    Returns {"hks": (L, n_times) float64, "wks": (L, n_energies) float64, "evals": (k,) 1/area units}.
    """
    surface = IntrinsicMesh(V, F)
    evals, evecs = laplacian.eigenpairs(surface.V, surface.F, k=k)
    at = evecs[surface.to_sub(landmark_vids, what="landmark")]
    return {"hks": descriptors.hks(evals, at, n_times=n_times).astype(np.float64),
            "wks": descriptors.wks(evals, at, n_energies=n_energies, variance=wks_variance).astype(np.float64),
            "evals": np.asarray(evals)}


def geodesic_features(V: np.ndarray, F: np.ndarray, landmark_vids: np.ndarray) -> dict:
    """Landmark geodesic distances normalized by the geodesic diameter, and landmark chirality.

    Returns {"D": (L,L) float (symmetric, zero diagonal), "diameter": float (length units of V),
    "chirality": (L,L,L) float}.
    """
    solver = GeodesicSolver(V, F)
    vids = np.asarray(landmark_vids, dtype=np.int64)
    solver.surface.to_sub(vids, what="landmark")
    D = solver.distances(vids)[:, vids]
    D = 0.5 * (D + D.T)  # the heat method's small asymmetry averaged out
    np.fill_diagonal(D, 0.0)
    diameter = solver.diameter()
    return {"D": D / diameter, "diameter": float(diameter), "chirality": landmark_chirality(V, F, vids)}


def flattening_features(V: np.ndarray, F: np.ndarray, landmark_vids: np.ndarray, Z: np.ndarray | None = None,
                        sample_vids: np.ndarray | None = None, *, n_samples: int = 300) -> dict:
    """Mid-edge flattening (one complex point per edge, ``midedge.midedge_flatten``) and surface samples.

    Z: (E,) complex, a given flattening with the same edge numbering to use instead of the computed one.
    sample_vids: (S,) int vertices whose edges are the samples (those off the kept component are left out);
    None: ``n_samples`` farthest-point samples of the edge midpoints, started at the midpoint farthest from their
    mean.
    Returns {"Z": (E,2) float (x, y), "lam": (E,) local scale of the flattening (planar length per unit
    surface length), "landmark_eids": (L,) int, "sample_eids": (S,) int, "edges": (E,2) int original vertex
    ids} over the E edges of the kept component.
    """
    surface = IntrinsicMesh(V, F)
    landmark_local = surface.to_sub(landmark_vids, what="landmark")
    Z_computed, edges, face_edges, kept = midedge.midedge_flatten(surface.V, surface.F)
    Z = Z_computed if Z is None else np.asarray(Z)
    lam = midedge.midedge_conformal_factor(surface.V, edges, face_edges, kept, Z, surface.F)
    if sample_vids is not None:
        sample_vids = np.asarray(sample_vids, dtype=np.int64)
        sample_local = surface.to_sub(sample_vids[surface.contains(sample_vids)])
        sample_eids = np.array([midedge.vertex_to_edge(int(v), edges) for v in sample_local], dtype=np.int64)
    else:
        M = midedge.edge_midpoints(surface.V, edges)
        start = int(np.argmax(np.linalg.norm(M - M.mean(axis=0), axis=1)))
        sample_eids = farthest_point_samples(M, n_samples, start=start)
    eids = np.array([midedge.vertex_to_edge(int(v), edges) for v in landmark_local], dtype=np.int64)
    return {"Z": np.stack([Z.real, Z.imag], axis=1), "lam": lam, "landmark_eids": eids,
            "sample_eids": np.asarray(sample_eids, dtype=np.int64),
            "edges": surface.vids[edges].astype(np.int64)}
