"""The rest-pose mesh: the implicit body's x >= 0 half by marching cubes, mirrored, relaxed onto the surface."""
from __future__ import annotations

import numpy as np

from corr_core.generate.humanoid.surface import body_sdf
from corr_core.geometry.primitives import largest_component, vertex_adjacency, vertex_normals


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


def _project_to_surface(P: np.ndarray, *, iters: int = 2, eps: float = 1e-5) -> np.ndarray:
    """Newton-project points P: (n,3) onto the zero set of ``body_sdf`` (forward-difference gradient)."""
    n = len(P)
    for _ in range(iters):
        vals = body_sdf(np.concatenate([P, P + [eps, 0, 0], P + [0, eps, 0], P + [0, 0, eps]])).reshape(4, n)
        f = vals[0]
        g = (vals[1:] - f).T / eps
        P = P - (f / np.maximum((g * g).sum(1), 1e-12))[:, None] * g
    return P


def mirror_pairs(V: np.ndarray, *, tol: float = 1e-5) -> np.ndarray | None:
    """(n,) index of each vertex's mirror image (x -> -x) in V: (n,3), or None if the set is not symmetric."""
    from scipy.spatial import cKDTree

    dist, pair = cKDTree(V).query(V * [-1.0, 1.0, 1.0])
    if dist.max() > tol or np.any(pair[pair] != np.arange(len(V))):
        return None
    return pair


def _relax(V: np.ndarray, F: np.ndarray, *, iters: int = 6, step: float = 0.5) -> np.ndarray:
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


def make_humanoid_rest(*, grid_step: float = DEFAULT_GRID_STEP) -> tuple[np.ndarray, np.ndarray]:
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
