"""Per-mesh data for dense correspondence, computed once per mesh and passed to every step.

``MeshBasis`` bundles a mesh with what the dense methods need of it: the Laplace-Beltrami eigenpairs (the
spectral basis), the lumped vertex areas, the surface area, a geodesic (heat-method) solver and a set of
farthest-point samples. Build it with ``mesh_basis(V, F, k)``; it holds numpy arrays only (plus the lazily built
``GeodesicSolver``, which is not pickled).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from corr_core.geometry import geodesic
from corr_core.geometry.laplacian import eigenpairs, laplacian_and_mass
from corr_core.geometry.primitives import face_areas, face_normals
from corr_core.geometry.sampling import farthest_point_samples


@dataclass
class MeshBasis:
    """One mesh and its spectral basis.

    Attributes:
        V: (n,3) float vertex positions (length units).
        F: (m,3) int triangles.
        evals: (k,) float ascending Laplace-Beltrami eigenvalues (1/area units).
        evecs: (n,k) float, M-orthonormal eigenvectors (evecs.T @ diag(mass) @ evecs = I).
        mass: (n,) float lumped vertex areas (area units).
        area: float total surface area; ``sqrt(area)`` is the length unit of every error measure.
        samples: (s,) int farthest-point vertex samples (Euclidean, deterministic start).
    """

    V: np.ndarray
    F: np.ndarray
    evals: np.ndarray
    evecs: np.ndarray
    mass: np.ndarray
    area: float
    samples: np.ndarray
    _solver: object = field(default=None, repr=False, compare=False)
    _sample_distances: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def n(self) -> int:
        return len(self.V)

    @property
    def scale(self) -> float:
        """sqrt(surface area): the length unit of normalized distances."""
        return float(np.sqrt(self.area))

    def solver(self):
        """The heat-method geodesic solver of this mesh (built on first use, then reused)."""
        if self._solver is None:
            self._solver = geodesic.GeodesicSolver(self.V, self.F)
        return self._solver

    def distances(self, sources) -> np.ndarray:
        """Geodesic distances / sqrt(area) from each source vertex: (s,) int -> (s, n) float."""
        return self.solver().distances(sources) / self.scale

    def sample_distances(self, m: int) -> np.ndarray:
        """Distances / sqrt(area) from the first ``m`` samples: (m, n) float, cached (the template's are reused
        for every target)."""
        have = 0 if self._sample_distances is None else len(self._sample_distances)
        if m > have:
            more = self.distances(self.samples[have:m])
            self._sample_distances = more if have == 0 else np.vstack([self._sample_distances, more])
        return self._sample_distances[:m]

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_solver"] = None
        return state


def _check_mesh(V: np.ndarray, F: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) < 4:
        raise ValueError(f"{name}: V must be (n,3) with n >= 4, got shape {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise ValueError(f"{name}: F must be (m,3) triangles, got shape {F.shape}")
    if F.min() < 0 or F.max() >= len(V):
        raise ValueError(f"{name}: face indices must be in 0..{len(V) - 1}, got {F.min()}..{F.max()}")
    if not np.all(np.isfinite(V)):
        raise ValueError(f"{name}: vertex positions contain NaN or inf")
    return V, F


def mesh_basis(V: np.ndarray, F: np.ndarray, k: int = 100, n_samples: int = 2000, name: str = "mesh") -> MeshBasis:
    """Eigenpairs, vertex areas and farthest-point samples of one mesh.

    Args:
        V: (n,3) float; F: (m,3) int, consistently oriented triangles (orientation decides left from right).
        k: number of eigenpairs (clipped to n - 1).
        n_samples: farthest-point samples used by the refinement (clipped to n).
        name: used in error messages.
    Returns:
        MeshBasis.
    """
    V, F = _check_mesh(V, F, name)
    _, M = laplacian_and_mass(V, F)
    evals, evecs = eigenpairs(V, F, k=min(k, len(V) - 1))
    mass = np.asarray(M.diagonal(), dtype=np.float64)
    start = int(np.argmax(np.linalg.norm(V - V.mean(axis=0), axis=1)))
    samples = farthest_point_samples(V, min(n_samples, len(V)), start=start)
    return MeshBasis(V=V, F=F, evals=np.asarray(evals), evecs=np.asarray(evecs), mass=mass,
                     area=float(face_areas(V, F).sum()), samples=samples)


def face_gradients(basis: MeshBasis, funcs: np.ndarray) -> np.ndarray:
    """Per-face gradients of piecewise-linear vertex functions.

    Args: basis: the mesh; funcs: (n, q) float vertex values.
    Returns: (m, 3, q) float, gradient in each face (units: function per length).
    """
    V, F = basis.V, basis.F
    N = face_normals(V, F)                                        # (m,3) unit
    twice_area = 2.0 * face_areas(V, F)
    grad = np.zeros((len(F), 3, funcs.shape[1]))
    for c in range(3):                                            # grad f = sum_c f_c (n x e_c) / (2A)
        e = V[F[:, (c + 2) % 3]] - V[F[:, (c + 1) % 3]]           # edge opposite corner c, along the face
        w = np.cross(N, e) / np.maximum(twice_area, 1e-300)[:, None]
        grad += w[:, :, None] * funcs[F[:, c]][:, None, :]
    return grad
