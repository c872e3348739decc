"""Mid-edge uniformization: a discrete conformal flattening of a genus-0 mesh onto the complex plane.

Method (Polthier's conjugate harmonic maps, as used by Lipman & Funkhouser, "Möbius Voting for Surface
Correspondence", SIGGRAPH 2009, section 4):

1. Cut: remove one *seed* face ``(a, b, c)``. Its vertices ``v1 < v2`` (the two smallest vertex ids) get the
   Dirichlet values ``u(v1) = -1``, ``u(v2) = +1``; every other vertex is free.
2. ``u``: the conforming (piecewise-linear, per-vertex) discrete harmonic function, ``L u = 0`` with the cotan
   Laplacian of the mesh *without* the seed face. Vertices on a boundary (holes) get the natural (Neumann)
   condition, so a hole maps to a horizontal slit. ``u`` behaves like the real part of a dipole ``1/z`` at the
   seed face, which is therefore sent towards infinity.
3. ``v``: Polthier's conjugate harmonic function, a non-conforming (Crouzeix-Raviart) function with one value
   per edge midpoint. In every face ``u`` is linear and ``v`` is the linear function with ``grad v = n x grad u``
   (``n`` = unit face normal, right-hand rule over the face's vertex order), so ``u + i v`` is exactly
   complex-linear on each mid-edge triangle. The per-face differences of ``v`` between the three midpoints are
   integrated over the mid-edge graph (all faces but the seed face) by sparse least squares; because ``u`` is
   discrete harmonic the differences are consistent (zero residual up to round-off), which the cotan formula
   guarantees (Polthier). The additive constant is fixed by ``v = 0`` at the midpoint of edge ``(v1, v2)``,
   which also has ``u = 0``: that midpoint is the origin ``Z = 0``.
4. Output ``Z[e] = u(midpoint e) + i v(e)`` with ``u(midpoint) = (u_a + u_b) / 2``.

Edge numbering (same as the course's flattened meshes): walk the faces in order, and in each face its edges
``(a, b), (b, c), (c, a)``; an edge gets the next id the first time it is seen. ``edges[e]`` holds the
vertex pair in the order first seen. Faces removed as the cut are still used for numbering.

Default cut (``cut_faces=None``): the seed face is the face whose centroid is nearest the mesh's
area-weighted surface centroid (for a standing human: the belly), and the output drops the seed face and its
(up to 3) edge neighbours, because faces touching the seed face lie next to the pole and are stretched to
enormous size. This is the 4-face cut of the course's oracle files. The seed face alone is removed from the
computation; the neighbours still take part, so the seed face's edges also get a ``Z`` value.

Orientation: the map is holomorphic w.r.t. the face orientation (counter-clockwise faces seen from the
normal stay counter-clockwise in the plane), so a mirror-symmetric partner (left/right) is *not* a Möbius
image: Möbius maps never flip orientation.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from corr_core.geometry.laplacian import cotan_laplacian
from corr_core.geometry.primitives import face_areas, mesh_edges, surface_centroid


def edge_midpoints(V: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Midpoints of edges. V: (n,3) float, edges: (n_edges,2) int -> (n_edges,3) float."""
    V = np.asarray(V, dtype=float)
    return 0.5 * (V[edges[:, 0]] + V[edges[:, 1]])


def vertex_to_edge(vid, edges: np.ndarray, F: np.ndarray | None = None):
    """An edge incident to each vertex: the lowest edge id among the vertex's edges.

    With the first-appearance numbering of ``mesh_edges`` this is the first edge of the first face that holds
    the vertex. ``F`` is accepted for API symmetry and not needed.

    Args:
        vid: int or (k,) int vertex ids.
        edges: (n_edges, 2) int.
    Returns:
        eid: int or (k,) int. Raises ValueError for a vertex on no edge.
    """
    edges = np.asarray(edges)
    n = int(edges.max()) + 1
    best = np.full(max(n, int(np.max(vid)) + 1), np.iinfo(np.int64).max, dtype=np.int64)
    ids = np.arange(len(edges), dtype=np.int64)
    np.minimum.at(best, edges[:, 0], ids)
    np.minimum.at(best, edges[:, 1], ids)
    out = best[np.asarray(vid)]
    if np.any(out == np.iinfo(np.int64).max):
        raise ValueError("vertex_to_edge: a vertex lies on no edge")
    return int(out) if np.ndim(out) == 0 else out


def default_seed_face(V: np.ndarray, F: np.ndarray) -> int:
    """Index of the face whose centroid is nearest the area-weighted surface centroid (index-free choice)."""
    V = np.asarray(V, dtype=float)
    center = surface_centroid(V, F)
    return int(np.argmin(np.linalg.norm(V[F].mean(axis=1) - center, axis=1)))


def face_neighbors(face_edges: np.ndarray, f: int) -> np.ndarray:
    """Faces sharing an edge with face ``f``. face_edges: (m,3) int -> (<=3,) int."""
    hit = np.isin(face_edges, face_edges[f]).any(axis=1)
    hit[f] = False
    return np.flatnonzero(hit)


def conjugate_differences(V: np.ndarray, F: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Per-face differences of the conjugate harmonic function between edge midpoints.

    In face (a,b,c) with midpoints m_ab, m_bc, m_ca: ``grad v = n x grad u = -(1/2A) sum_i u_i e_i`` where
    ``e_i`` is the edge opposite corner i, oriented along the face. Returns (m, 3) float:
    ``[v(m_bc) - v(m_ab), v(m_ca) - v(m_bc), v(m_ab) - v(m_ca)]``.
    """
    P = np.asarray(V, dtype=float)[F]                                   # (m,3,3)
    e = np.stack([P[:, 2] - P[:, 1], P[:, 0] - P[:, 2], P[:, 1] - P[:, 0]], axis=1)   # opposite corner i
    twice_area = np.linalg.norm(np.cross(e[:, 0], e[:, 1]), axis=1)
    uf = u[F]
    jgrad = -np.einsum("mi,mij->mj", uf, e) / np.maximum(twice_area, 1e-300)[:, None]
    # m_bc - m_ab = (c - a)/2 = -e_b/2 ; m_ca - m_bc = (a - b)/2 = -e_c/2 ; m_ab - m_ca = (b - c)/2 = -e_a/2
    steps = -0.5 * e[:, [1, 2, 0]]
    return np.einsum("mj,mkj->mk", jgrad, steps)


def midedge_flatten(V: np.ndarray, F: np.ndarray, cut_faces=None, seed_face: int | None = None,
                    return_info: bool = False):
    """Mid-edge conformal flattening (see module docstring).

    Args:
        V: (n, 3) float vertex positions.
        F: (m, 3) int faces, consistently oriented; the mesh must be connected and of genus 0 (closed, or
            with holes: each hole becomes a slit).
        cut_faces: faces to drop from the output. ``None``: the seed face and its edge neighbours.
        seed_face: the face removed from the computation (its vertices carry the Dirichlet values).
            ``None``: ``cut_faces[0]`` if cut_faces is given, else ``default_seed_face(V, F)``.
        return_info: also return a dict (seed_face, u (n,), conjugate residual).
    Returns:
        Z: (n_edges,) complex128, flattened position of each edge midpoint.
        edges: (n_edges, 2) int vertex pairs (first-appearance numbering).
        face_edges: (m', 3) int, mid-edge faces (e_ab, e_bc, e_ca) of the kept faces.
        kept_faces: (m',) int, original indices of the kept faces (increasing).
    """
    V = np.asarray(V, dtype=float)
    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    edges, fe_all = mesh_edges(F)
    if seed_face is None:
        seed_face = int(np.atleast_1d(cut_faces)[0]) if cut_faces is not None else default_seed_face(V, F)
    if cut_faces is None:
        cut_faces = np.concatenate([[seed_face], face_neighbors(fe_all, seed_face)])
    cut_faces = np.unique(np.asarray(cut_faces, dtype=np.int64))

    keep_calc = np.ones(m, bool)
    keep_calc[seed_face] = False
    Fc = F[keep_calc]
    v1, v2 = np.sort(F[seed_face])[:2]

    # harmonic u with u(v1) = -1, u(v2) = +1
    L = cotan_laplacian(V, Fc).tocsr()
    n = len(V)
    fixed = np.array([v1, v2])
    free = np.setdiff1d(np.arange(n), fixed)
    u = np.zeros(n)
    u[fixed] = [-1.0, 1.0]
    rhs = -L[free][:, fixed] @ u[fixed]
    u[free] = spla.spsolve(L[free][:, free].tocsc(), rhs)

    # conjugate v on midpoints: least squares over per-face differences
    fe = fe_all[keep_calc]
    d = conjugate_differences(V, Fc, u).ravel()
    src = fe.ravel()                               # m_ab, m_bc, m_ca
    dst = fe[:, [1, 2, 0]].ravel()                 # m_bc, m_ca, m_ab
    ne = len(edges)
    k = len(d)
    B = sp.csr_matrix((np.r_[np.ones(k), -np.ones(k)], (np.r_[np.arange(k), np.arange(k)], np.r_[dst, src])),
                      shape=(k, ne))
    pin = int(np.flatnonzero(((edges[:, 0] == v1) & (edges[:, 1] == v2)) |
                             ((edges[:, 0] == v2) & (edges[:, 1] == v1)))[0])
    cols = np.setdiff1d(np.arange(ne), [pin])
    Bf = B[:, cols].tocsc()
    v = np.zeros(ne)
    v[cols] = spla.spsolve((Bf.T @ Bf).tocsc(), Bf.T @ d)
    residual = float(np.abs(B @ v - d).max()) if k else 0.0

    Z = 0.5 * (u[edges[:, 0]] + u[edges[:, 1]]) + 1j * v
    kept = np.setdiff1d(np.arange(m), cut_faces)
    out = (Z, edges, fe_all[kept], kept)
    if return_info:
        return out + ({"seed_face": int(seed_face), "u": u, "conjugate_residual": residual,
                       "dirichlet_vertices": (int(v1), int(v2))},)
    return out


def midedge_conformal_factor(V: np.ndarray, edges: np.ndarray, face_edges: np.ndarray, kept_faces: np.ndarray,
                             Z: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Local scale of the flattening at each mid-edge point: planar length per unit surface length.

    Per kept face: ``sqrt(area of the flattened mid-edge triangle / area of the 3D mid-edge triangle)`` (the
    map is a similarity on each mid-edge triangle, so this is its scale factor). Per edge: the geometric mean
    over the kept faces that hold it; edges on no kept face get the median factor.

    Args:
        V: (n,3), edges: (n_edges,2), face_edges: (m',3) and kept_faces: (m',) from ``midedge_flatten``,
        Z: (n_edges,) complex, F: (m,3) original faces.
    Returns:
        (n_edges,) float > 0.
    """
    V = np.asarray(V, dtype=float)
    Fk = np.asarray(F)[kept_faces]
    area3 = 0.25 * face_areas(V, Fk)  # a mid-edge triangle has a quarter of its face's area
    P = Z[face_edges]
    area2 = 0.5 * np.abs(np.imag(np.conj(P[:, 1] - P[:, 0]) * (P[:, 2] - P[:, 0])))
    logf = 0.5 * np.log(np.maximum(area2, 1e-300) / np.maximum(area3, 1e-300))
    s = np.zeros(len(edges))
    c = np.zeros(len(edges))
    np.add.at(s, face_edges.ravel(), np.repeat(logf, 3))
    np.add.at(c, face_edges.ravel(), 1.0)
    out = np.full(len(edges), np.nan)
    out[c > 0] = np.exp(s[c > 0] / c[c > 0])
    out[c == 0] = np.nanmedian(out)
    return out
