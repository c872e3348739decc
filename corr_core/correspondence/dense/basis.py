"""Per-mesh data for dense correspondence, computed once per mesh and passed to every step.

``MeshBasis`` bundles a mesh with what the dense methods need of it: the Laplace-Beltrami eigenpairs (the
spectral basis), the lumped vertex areas, the surface area, a geodesic (heat-method) solver and a set of
farthest-point samples. Build it with ``mesh_basis(V, F, k)``; it holds numpy arrays only (plus the lazily built
``GeodesicSolver``, which is not pickled), and ``to_arrays`` / ``from_arrays`` turn it into a plain dict of numpy
arrays and back (for caches such as zarr).

Vertex ids: the basis is computed on the mesh's largest connected component of referenced vertices
(``corr_core.geometry.intrinsic.IntrinsicMesh``), so a mesh with loose pieces or unused vertices works. Every
array of the basis (V, evecs, mass, samples, and the point maps between bases) uses the *local* ids 0..n-1 of that
component; ``vids`` gives their original ids. ``to_local`` converts original ids (e.g. landmark files) to local
ones, ``map_to_original`` a local point map to original ids. On a clean mesh both are the identity.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse.linalg as sla
from scipy.spatial import cKDTree

from corr_core.correspondence.dense.nearest import PointTree, RowCells
from corr_core.geometry import geodesic
from corr_core.geometry.intrinsic import IntrinsicMesh
from corr_core.geometry.laplacian import laplacian_and_mass, start_vector
from corr_core.geometry.primitives import face_areas, face_normals, vertex_normals
from corr_core.geometry.repair import coincident_representatives, orient_outward
from corr_core.geometry.sampling import farthest_point_samples

# Rows ``MeshBasis.point_distances`` keeps per basis: a pair needs a dozen (the extremities or given points of
# both meshes); the limit bounds a long-lived template's memory (32 rows of n float64) whatever it is asked.
MAX_KEPT_DISTANCE_ROWS = 32


@dataclass
class MeshBasis:
    """One mesh and its spectral basis.

    Attributes:
        V: (n,3) float vertex positions, in the mesh's units divided by a power of two that brings sqrt(area)
            into [1, 2) (``size_exponent``; none for meshes already that size).
        F: (m,3) int triangles.
        evals: (k,) float ascending Laplace-Beltrami eigenvalues (1/area units).
        evecs: (n,k) float, M-orthonormal eigenvectors (evecs.T @ diag(mass) @ evecs = I).
        mass: (n,) float lumped vertex areas (area units).
        area: float total surface area; ``sqrt(area)`` is the length unit of every error measure.
        samples: (s,) int farthest-point vertex samples (Euclidean, deterministic start).
        vids: (n,) int original vertex id of each local vertex (None: the identity, nothing was left out).
        n_full: vertex count of the original mesh (None: n).
        aliases: (n_full,) int original id each original vertex stands for (None: itself): a copy of a vertex
            at exactly its position (a seam, ``repair.coincident_representatives``) is its representative's alias,
            takes its image in ``map_to_original`` and its local id in ``to_local``.
    """

    V: np.ndarray
    F: np.ndarray
    evals: np.ndarray
    evecs: np.ndarray
    mass: np.ndarray
    area: float
    samples: np.ndarray
    vids: np.ndarray | None = None
    n_full: int | None = None
    aliases: np.ndarray | None = None
    _solver: object = field(default=None, repr=False, compare=False)
    _sample_distances: np.ndarray | None = field(default=None, repr=False, compare=False)
    _derived: dict = field(default_factory=dict, repr=False, compare=False)

    def cached(self, key, make):
        """``make()`` computed once per basis and ``key`` (derived data a template reuses for every target, e.g.
        its factorized ARAP operators or its extremities); not serialized."""
        if key not in self._derived:
            self._derived[key] = make()
        return self._derived[key]

    @property
    def n(self) -> int:
        return len(self.V)

    @property
    def scale(self) -> float:
        """sqrt(surface area): the length unit of normalized distances."""
        return float(np.sqrt(self.area))

    def normals(self) -> np.ndarray:
        """Unit vertex normals (n,3) float (``primitives.vertex_normals``), made on first use and then shared,
        read-only, by every refinement step and starting map of this mesh."""
        def make() -> np.ndarray:
            N = vertex_normals(self.V, self.F)
            N.setflags(write=False)
            return N
        return self.cached("vertex_normals", make)

    def tree(self):
        """A k-d tree of the vertices (n,3) (``nearest.PointTree``), made on first use and then shared by every
        refinement step and starting map of this mesh (a query's answer depends only on its point, so sharing
        changes no result)."""
        return self.cached("vertex_tree", lambda: PointTree(self.V))

    def vertex_cells(self, n_centres: int | None = None, n_regions: int | None = None):
        """The vertices partitioned into cells (``nearest.RowCells``, for ``fmaps.nearest_rows``' pruned search over
        all vertices): centres the first ``n_centres`` samples (None: half the samples), every vertex in the cell
        of its nearest centre (Euclidean), cells ranked by the nearest of the first ``n_regions`` samples (None:
        n_centres / 16) to their centre, then by centre. Made on first use, then shared. The partition only sets
        the speed: any gives the same answer.

        Half the samples and 1/16 of that: on generated other bodies at 1,000 samples, of 500 / 700 / 1000 centres
        x 32 / 64 / 128 regions, 500 / 32 and 500 / 64 were the fastest (x0.695 of the brute force's time, mean of
        6 seeds; `python bench/dense_searches.py --seeds 0-5 --poses 6 --centres 1000,700,500 --regions
        32,64,128`); on two course poses at 2,000 samples, of 2000 / 1000 / 700 x 32 / 64 / 128, 1000 / 64 and
        1000 / 128 (x0.294; `python bench/dense_searches.py --seeds '' --data ../shared/data/hw3/scape --pairs 2
        --centres 2000,1000,700 --regions 32,64,128`).
        """
        n_centres = max(1, len(self.samples) // 2) if n_centres is None else int(n_centres)
        n_regions = max(1, n_centres // 16) if n_regions is None else int(n_regions)

        def make():
            centres = np.array(self.samples[:n_centres], dtype=np.int64)
            owner = cKDTree(self.V[centres]).query(self.V)[1]
            owner[centres] = np.arange(len(centres))             # a centre owns itself, even beside a duplicate
            region = cKDTree(self.V[self.samples[:n_regions]]).query(self.V[centres])[1]
            rank = np.empty(len(centres), dtype=np.int64)
            rank[np.lexsort((np.arange(len(centres)), region))] = np.arange(len(centres))
            for a in (centres, owner, rank):
                a.setflags(write=False)
            return RowCells(centres, owner, rank)
        return self.cached(("vertex_cells", n_centres, n_regions), make)

    def scaled(self, factor: float) -> "MeshBasis":
        """The same mesh and basis with every length multiplied by ``factor`` > 0: V * factor, area and mass *
        factor^2, eigenvalues / factor^2, eigenvectors / factor (still M-orthonormal); samples, ids and the
        distances / sqrt(area) carried over. Exact (bit for bit) when ``factor`` is a power of two."""
        f = float(factor)
        out = MeshBasis(V=self.V * f, F=self.F, evals=self.evals / (f * f), evecs=self.evecs / f,
                        mass=self.mass * (f * f), area=self.area * (f * f), samples=self.samples, vids=self.vids,
                        n_full=self.n_full, aliases=self.aliases)
        out._sample_distances = self._sample_distances
        for key in ("vertex_normals", "extremities"):                  # unchanged by a scale
            if key in self._derived:
                out._derived[key] = self._derived[key]
        return out

    def solver(self):
        """The heat-method geodesic solver of this mesh (built on first use, then reused)."""
        if self._solver is None:
            self._solver = geodesic.GeodesicSolver(self.V, self.F)
        return self._solver

    def distances(self, sources) -> np.ndarray:
        """Geodesic distances / sqrt(area) from each source vertex: (s,) int -> (s, n) float."""
        return self.solver().distances(sources) / self.scale

    def point_distances(self, points) -> np.ndarray:
        """``distances(points)``, each vertex's row computed once and then kept (read-only): (p,) int -> (p, n) float.

        For the few feature points a pair asks for more than once (a template's extremities or given points,
        reused for every target; a target's extremities, found and then used). Each row is one heat-method solve
        from its own vertex, so a kept row is the one ``distances`` gives, bit for bit. At most
        ``MAX_KEPT_DISTANCE_ROWS`` rows are kept per basis; later ones are computed every time."""
        points = np.atleast_1d(np.asarray(points, dtype=np.int64)).tolist()
        if not points:
            return np.empty((0, self.n))
        rows = self.cached("point_distance_rows", dict)
        missing = [v for v in dict.fromkeys(points) if v not in rows]
        fresh = dict(zip(missing, self.distances(missing))) if missing else {}
        for v, row in fresh.items():
            if len(rows) < MAX_KEPT_DISTANCE_ROWS:
                row.setflags(write=False)
                rows[v] = row
        return np.stack([rows[v] if v in rows else fresh[v] for v in points])

    def face_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-face geometry of piecewise-linear gradients, made on first use and then shared (read-only): unit
        face normals N (m,3) float and corner weights W (3, m, 3) float, W[c] = (N x e_c) / (2 area) with e_c the
        edge opposite corner c, so that the gradient of vertex values f in each face is sum_c f[F[:, c]] W[c]
        (``face_gradients``), in 1 / length units."""
        def make() -> tuple[np.ndarray, np.ndarray]:
            N = face_normals(self.V, self.F)
            twice_area = 2.0 * face_areas(self.V, self.F)
            W = np.stack([np.cross(N, self.V[self.F[:, (c + 2) % 3]] - self.V[self.F[:, (c + 1) % 3]])
                          / np.maximum(twice_area, 1e-300)[:, None] for c in range(3)])
            N.setflags(write=False)
            W.setflags(write=False)
            return N, W
        return self.cached("face_frames", make)

    def sample_distances(self, m: int) -> np.ndarray:
        """Distances / sqrt(area) from the first ``m`` samples: (m, n) float, cached (the template's are reused
        for every target)."""
        have = 0 if self._sample_distances is None else len(self._sample_distances)
        if m > have:
            more = self.distances(self.samples[have:m])
            self._sample_distances = more if have == 0 else np.vstack([self._sample_distances, more])
        return self._sample_distances[:m]

    def __post_init__(self):
        if self.vids is None:
            self.vids = np.arange(len(self.V), dtype=np.int64)
        self.vids = np.asarray(self.vids, dtype=np.int64)
        self.n_full = len(self.V) if self.n_full is None else int(self.n_full)
        if len(self.vids) != len(self.V) or (len(self.vids) and self.vids.max() >= self.n_full):
            raise ValueError(f"MeshBasis: vids must be ({len(self.V)},) ids below n_full={self.n_full}")
        if self.aliases is not None:
            self.aliases = np.asarray(self.aliases, dtype=np.int64)
            if self.aliases.shape != (self.n_full,) or np.any(self.aliases[self.aliases] != self.aliases):
                raise ValueError(f"MeshBasis: aliases must be ({self.n_full},) ids, each its own representative's")

    def to_local(self, vids, what: str = "vertex", names=None, source: str = "") -> np.ndarray:
        """Local ids (p,) int64 of original vertex ids (p,) int; a clear error (naming ``what``, ``names``,
        ``source``) for an id that is not on the kept component."""
        vids = np.asarray(vids, dtype=np.int64)
        bad = (vids < 0) | (vids >= self.n_full)
        if bad.any():
            raise ValueError(f"{what} id {int(vids[bad][0])}{' from ' + source if source else ''} is outside the "
                             f"mesh's 0..{self.n_full - 1} vertices")
        local = np.full(self.n_full, -1, dtype=np.int64)
        local[self.vids] = np.arange(self.n)
        out = local[vids if self.aliases is None else self.aliases[vids]]
        if (out < 0).any():
            i = int(np.flatnonzero(out < 0)[0])
            label = f"{what} {names[i]!r} (vertex {int(vids[i])})" if names is not None else f"{what} {int(vids[i])}"
            raise ValueError(f"{label}{' from ' + source if source else ''} is not on the mesh's largest connected "
                             f"component ({self.n} of {self.n_full} vertices): it lies on a loose piece or no face "
                             f"uses it; move it onto the main surface or remove the loose piece")
        return out

    _ARRAY_KEYS = ("V", "F", "evals", "evecs", "mass", "area", "samples", "vids", "n_full")

    def to_arrays(self) -> dict:
        """The basis as a plain dict of numpy arrays (``area`` and ``n_full`` as 0-d arrays; the template's cached
        sample distances as ``sample_distances``, its ``init.extremities`` as ``extremities`` and the distance rows
        ``point_distances`` kept as ``point_distance_ids`` (p,) int / ``point_distance_rows`` (p, n) when computed).
        ``MeshBasis.from_arrays`` inverts it exactly."""
        out = {key: np.asarray(getattr(self, key)) for key in self._ARRAY_KEYS}
        if self._sample_distances is not None:
            out["sample_distances"] = np.asarray(self._sample_distances)
        if "extremities" in self._derived:
            out["extremities"] = np.asarray(self._derived["extremities"])
        rows = self._derived.get("point_distance_rows")
        if rows:
            out["point_distance_ids"] = np.array(list(rows), dtype=np.int64)
            out["point_distance_rows"] = np.stack(list(rows.values()))
        if self.aliases is not None:
            out["aliases"] = np.asarray(self.aliases)
        return out

    @classmethod
    def from_arrays(cls, arrays, source: str = "MeshBasis arrays") -> "MeshBasis":
        """Inverse of ``to_arrays``: arrays is a mapping with the keys of ``to_arrays`` (e.g. a zarr group)."""
        missing = [key for key in cls._ARRAY_KEYS if key not in arrays]
        if missing:
            raise ValueError(f"{source}: missing {missing}; rebuild it with mesh_basis(V, F) and to_arrays()")
        d = {key: np.asarray(arrays[key]) for key in cls._ARRAY_KEYS}
        basis = cls(V=d["V"].astype(np.float64), F=d["F"].astype(np.int64), evals=d["evals"], evecs=d["evecs"],
                    mass=d["mass"], area=float(d["area"]), samples=d["samples"].astype(np.int64),
                    vids=d["vids"], n_full=int(d["n_full"]),
                    aliases=np.asarray(arrays["aliases"]) if "aliases" in arrays else None)
        if "sample_distances" in arrays:
            basis._sample_distances = np.asarray(arrays["sample_distances"])
        if "extremities" in arrays:
            basis._derived["extremities"] = np.asarray(arrays["extremities"], dtype=np.int64)
        if "point_distance_ids" in arrays:
            rows = np.array(arrays["point_distance_rows"], dtype=np.float64)
            rows.setflags(write=False)
            basis._derived["point_distance_rows"] = dict(zip(np.asarray(arrays["point_distance_ids"]).tolist(), rows))
        return basis

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_solver"] = None
        state["_derived"] = {}
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
    return V, F


def basis_eigenpairs(L, M, k: int, area: float) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest eigenpairs of ``L phi = lambda M phi`` (the dense basis; same problem and fixed start
    vector as ``corr_core.geometry.laplacian.eigenpairs``, solved faster).

    Shift-invert Lanczos (scipy ``eigsh``) around ``sigma = 0.4 * lambda_weyl``, the middle of the wanted band
    rather than its bottom: Weyl's law for a surface, ``lambda_k ~ 4 pi k / area``, estimates its top, and the
    Ritz values then converge in fewer restarts (with the symmetric ordering below: about 2x faster than
    ``eigenpairs`` for k = 100 on the course meshes' 12,500 vertices, the same eigenpairs to 1e-12). The ``k``
    eigenvalues nearest ``sigma`` are the ``k`` smallest exactly when the farthest of them is at least ``sigma``
    away (the spectrum is >= 0); when Weyl's estimate is too high for a mesh (e.g. long open boundaries) this
    check fails and the solve is redone around ``sigma = -1e-6``, as ``eigenpairs`` does. ``L - sigma M`` is
    factorized once by SuperLU with a symmetric ordering (fewer fill-ins than the default column ordering).

    Args: L: (n,n) sparse PSD stiffness; M: (n,n) sparse diagonal mass; k: 1 <= k < n; area: surface area.
    Returns: evals (k,) ascending, clipped at 0 (1/area units); evecs (n,k) M-orthonormal.
    """
    n = L.shape[0]
    if not 0 < k < n:
        raise ValueError(f"k must be in 1..{n - 1}, got {k}")
    L, M = L.tocsc(), M.tocsc()
    sigma = 0.4 * 4.0 * np.pi * k / max(area, 1e-300)
    try:
        evals, evecs = _shift_invert_eigsh(L, M, k, sigma=sigma)
        found_bottom = np.max(np.abs(evals - sigma)) >= sigma * (1.0 - 1e-9)   # the k nearest reach down to 0
    except (sla.ArpackNoConvergence, RuntimeError):
        found_bottom = False
    if not found_bottom:
        evals, evecs = _shift_invert_eigsh(L, M, k, sigma=-1e-6)   # just below 0: L - sigma M is regular
    order = np.argsort(evals, kind="stable")
    evals, evecs = np.maximum(evals[order], 0.0), evecs[:, order]
    norms = np.sqrt(np.einsum("ik,ik->k", evecs, M @ evecs))
    return evals, evecs / norms


def _shift_invert_eigsh(L, M, k: int, *, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """The k eigenpairs of ``L phi = lambda M phi`` nearest ``sigma`` (unsorted), fixed start vector."""
    lu = sla.splu((L - sigma * M).tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1,
                  options={"SymmetricMode": True})
    op = sla.LinearOperator(L.shape, matvec=lu.solve, dtype=np.float64)
    return sla.eigsh(L, k=k, M=M, sigma=sigma, which="LM", v0=start_vector(L.shape[0]), OPinv=op)


def mesh_basis(V: np.ndarray, F: np.ndarray, *, k: int = 100, n_samples: int = 2000, name: str = "mesh") -> MeshBasis:
    """Eigenpairs, vertex areas and farthest-point samples of one mesh.

    Args:
        V: (n,3) float; F: (m,3) int, consistently oriented triangles (orientation decides left from right).
        k: number of eigenpairs (clipped to n - 1), by ``basis_eigenpairs``.
        n_samples: farthest-point samples used by the refinement (clipped to n).
        name: used in error messages.
    Returns:
        MeshBasis of the largest connected component (module docstring: local and original ids).
    """
    V, F = _check_mesh(V, F, name)
    F, aliases = _welded(V, F, name)
    mesh = IntrinsicMesh(V, F)
    V, F = mesh.V, mesh.F
    if not np.all(np.isfinite(V)):
        raise ValueError(f"{name}: vertex positions of the mesh's surface contain NaN or inf")
    if len(V) < 4:
        raise ValueError(f"{name}: the largest connected component has only {len(V)} vertices")
    F_outward, ratio = orient_outward(V, F)
    if F_outward is not F:
        warnings.warn(f"{name}: its faces point inward (signed volume ratio {ratio:.2f}); the dense map uses them "
                      "reversed (orientation tells left from right)", UserWarning, stacklevel=2)
        F = F_outward
    V = V * 2.0 ** -size_exponent(V, F, name)          # exact: a mesh with sqrt(area) in [1, 2) is left as it is
    L, M = laplacian_and_mass(V, F)
    area = float(face_areas(V, F).sum())
    evals, evecs = basis_eigenpairs(L, M, min(k, len(V) - 1), area)
    mass = np.asarray(M.diagonal(), dtype=np.float64)
    start = int(np.argmax(np.linalg.norm(V - V.mean(axis=0), axis=1)))
    samples = farthest_point_samples(V, min(n_samples, len(V)), start=start)
    return MeshBasis(V=V, F=F, evals=evals, evecs=evecs, mass=mass, area=area, samples=samples, vids=mesh.vids,
                     n_full=mesh.n_full, aliases=aliases)


def _welded(V: np.ndarray, F: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    """The surface welded along its seams: (F (m',3) re-pointed to ``repair.coincident_representatives``, without
    the faces that then repeat a vertex; aliases (n,) int or None when no two vertices share a position). A mesh
    the pipelines already welded (``repair_mesh(weld=True)``: the copies used by no face) gets its aliases too."""
    rep = coincident_representatives(V, F)
    if np.array_equal(rep, np.arange(len(V))):
        return F, None
    F = rep[F]
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 2] != F[:, 0])]
    if not len(F):
        raise ValueError(f"{name}: every face joins vertices at one position: the surface has no area")
    return F, rep


def size_exponent(V: np.ndarray, F: np.ndarray, name: str = "mesh") -> int:
    """k = floor(log2(sqrt(area))) of the surface V (n,3) float, F (m,3) int: ``mesh_basis`` keeps V / 2^k, whose
    sqrt(area) is in [1, 2), so the eigensolver and every tolerance of the dense steps see a mesh of the same size
    whatever its units (metres, millimetres, kilometres). A power of two scales exactly, and the meshes of the
    pipelines (sqrt(area) 1.1 to 1.5) have k = 0: their bases are unchanged, bit for bit."""
    area = float(face_areas(V, F).sum())
    if not (np.isfinite(area) and area > 0):
        raise ValueError(f"{name}: the mesh's surface has no area ({area}): its triangles are all degenerate")
    return int(np.floor(0.5 * np.log2(area)))


def units_exponent(source: MeshBasis, target: MeshBasis) -> int:
    """k such that 2^k is the power of two nearest to sqrt(source.area / target.area): the factor that brings the
    target's lengths to the template's units (a target in millimetres against a template in metres: k = -10)."""
    return int(np.round(0.5 * np.log2(source.area / target.area)))


def in_units_of(target: MeshBasis, source: MeshBasis) -> MeshBasis:
    """``target`` in the units of ``source``: scaled by 2^``units_exponent`` (``MeshBasis.scaled``, exact), made
    once per exponent and cached on ``target``; ``target`` itself when the two areas are within a factor of 2.

    The rigid patch fits and the ARAP registration compare the two meshes' positions, and the functional map's
    Laplacian term their eigenvalues, so a target in other units (a scan in millimetres, a template in metres)
    would get a wrong map. A power of two leaves meshes of comparable size exactly as they are (every map made
    so far, bit for bit) and changes nothing but the units; what remains is a size difference below a factor of
    sqrt(2) in length, which the maps absorb as they absorb people of other sizes.
    """
    k = units_exponent(source, target)
    if k == 0:
        return target
    return target.cached(("in_units", k), lambda: target.scaled(2.0 ** k))


SIZE_DEAD_ZONE = 1.0 / 32.0   # log2 of a length ratio: sizes within 2^(1/32) (2.2 % in length) count as equal


def size_exponent_gap(source: MeshBasis, target: MeshBasis) -> float:
    """log2 of the length ratio sqrt(source.area / target.area) minus its nearest integer (``units_exponent``):
    how far the two sizes are apart once the units agree, in [-0.5, 0.5] (0.26 for a person 1.2 times taller)."""
    e = 0.5 * np.log2(source.area / target.area)
    return float(e - np.round(e))


def in_size_of(target: MeshBasis, source: MeshBasis) -> MeshBasis:
    """``target`` scaled to the size of ``source``: lengths times sqrt(source.area / target.area), so it has the
    template's area; ``in_units_of`` (a power of two, exact) when the sizes agree within ``SIZE_DEAD_ZONE`` once
    the units agree. Made once and cached on ``target``.

    The dense map compares the two meshes' eigenvalues, spectral embeddings and positions (functional maps,
    ZoomOut, rigid patch fits, the ARAP registration), so a person 1.2 or 1.4 times the template's height got a
    worse map in its own size than at the template's (``python bench/dense_units.py``, docs/dense.md "Units and
    size"). Every
    measure of a map is per sqrt(area), so the scale changes nothing else. The dead zone keeps the maps of
    meshes of one subject in several poses (area within 4 % of the template's) bit for bit as they were.
    """
    if abs(size_exponent_gap(source, target)) <= SIZE_DEAD_ZONE:
        return in_units_of(target, source)
    factor = float(np.sqrt(source.area / target.area))
    return target.cached(("in_size", factor), lambda: target.scaled(factor))


def map_to_original(source: MeshBasis, target: MeshBasis, p2p: np.ndarray) -> np.ndarray:
    """A point map in local ids (n_s,) int -> in original ids (source.n_full,) int64: entry i is the original
    target vertex id of original template vertex i, -1 for template vertices off the template's kept component."""
    p2p = np.asarray(p2p, dtype=np.int64)
    if p2p.shape != (source.n,):
        raise ValueError(f"point map has shape {p2p.shape}, the template basis {source.n} vertices")
    out = np.full(source.n_full, -1, dtype=np.int64)
    out[source.vids] = target.vids[p2p]
    return out if source.aliases is None else out[source.aliases]


def map_to_local(source: MeshBasis, target: MeshBasis, vertex_map: np.ndarray) -> np.ndarray:
    """The inverse of ``map_to_original``: (source.n_full,) int original target ids -> (n_s,) int local ids.

    Raises ValueError when a vertex of the template's kept component maps off the target's kept component."""
    vertex_map = np.asarray(vertex_map, dtype=np.int64)
    if vertex_map.shape != (source.n_full,):
        raise ValueError(f"vertex map has shape {vertex_map.shape}, the template {source.n_full} vertices")
    return target.to_local(vertex_map[source.vids], what="mapped vertex")


def face_gradients(basis: MeshBasis, funcs: np.ndarray) -> np.ndarray:
    """Per-face gradients of piecewise-linear vertex functions.

    Args: basis: the mesh; funcs: (n, q) float vertex values.
    Returns: (m, 3, q) float, gradient in each face (units: function per length).
    """
    F = basis.F
    _, W = basis.face_frames()                                    # W[c] = (n x e_c) / (2A), e_c opposite corner c
    grad = np.zeros((len(F), 3, funcs.shape[1]))
    for c in range(3):                                            # grad f = sum_c f_c (n x e_c) / (2A)
        grad += W[c][:, :, None] * funcs[F[:, c]][:, None, :]
    return grad
