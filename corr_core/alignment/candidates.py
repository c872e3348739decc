"""Candidate pairs for large collections: which shape pairs get a rotation cost C_ij(theta) at all.

The complete graph costs N(N-1)/2 pairs; the solvers on a k-nearest-shapes graph are as accurate (docs/scale.md),
so at large N only the pairs of a *candidate graph* are computed:

- ``rotation_invariant_descriptor``: per shape, the magnitudes of the DFT of its view features F (V, D) along the
  view axis (a cyclic shift of the views, i.e. a rotation of the shape about +y, changes only the phases), scaled
  so that their Euclidean distance is a lower bound of min_theta C_ij(theta) (Parseval:
  C_ij(theta) = (1/V) sum_k w_k |A_k - B_k e^{i 2 pi k theta / V}|^2 >= (1/V) sum_k w_k (|A_k| - |B_k|)^2), then
  projected to ``dim`` (128) values by a fixed seeded Gaussian matrix (Johnson-Lindenstrauss: squared distances
  are kept in expectation). Deterministic: the matrix depends only on (input size, dim, seed).
- ``candidate_pairs``: the descriptors reduced to ``index_dim`` (32) principal components
  (``principal_components``), each shape's k nearest shapes in them (``nearest_pairs``: faiss, an exact flat index
  up to EXACT_MAX shapes, an HNSW graph index above; one thread, so the same input gives the same pairs), plus
  ``n_random`` uniformly random partners per shape (fixed seed: long-range pairs, and an unbiased sample of all
  pairs for the kernel width), plus bridges that make the graph connected.

Measured on 500 generated chairs (docs/scale.md): of each shape's 10 nearest shapes by min_theta C_ij, the full
magnitudes find 83 %, the 128-value projection 70 %, its 32 principal components 67 %; the median best cost of
the chosen pairs is 152 against 145 for the true nearest and 327 over all pairs.
"""
from __future__ import annotations

import functools

import numpy as np

__all__ = ["DESCRIPTOR_DIM", "rotation_invariant_descriptor", "projection_matrix", "principal_components",
           "nearest_pairs", "random_pairs",
           "bridge_pairs", "candidate_pairs", "complete_pairs", "PAIR_KINDS", "SAMPLE_KINDS"]

DESCRIPTOR_DIM = 128
INDEX_DIM = 32          # principal components the nearest-neighbour index searches in
EXACT_MAX = 20000       # up to this many shapes an exact (flat) index, above it HNSW
HNSW_PARAMS = {"M": 16, "efConstruction": 100, "efSearch": 64}   # recall 0.997 of the exact 10-NN at 100,000
# kinds of candidate pairs (the ``kind`` array of ``candidate_pairs``)
PAIR_KINDS = {"self": 0, "nearest": 1, "random": 2, "bridge": 3, "complete": 4}
# kinds whose pairs are a uniform sample of all pairs (the kernel width is their median cost)
SAMPLE_KINDS = (PAIR_KINDS["random"], PAIR_KINDS["complete"])


@functools.lru_cache(maxsize=4)
def projection_matrix(n_in: int, dim: int, *, seed: int = 0) -> np.ndarray:
    """(n_in, dim) float32 Gaussian matrix / sqrt(dim) from ``seed`` (cached per process; the same everywhere)."""
    rng = np.random.default_rng(seed)
    P = rng.standard_normal((n_in, dim), dtype=np.float32) / np.float32(np.sqrt(dim))
    P.setflags(write=False)
    return P


def _dft_magnitudes(F: np.ndarray) -> np.ndarray:
    """(..., V//2+1, D) float32: |rfft(F, axis=-2)| * sqrt(w_k / V), w_k = 2 except for k = 0 and the Nyquist
    frequency (1), so that the Euclidean distance of two results is <= min_theta sqrt(C_ij(theta))."""
    V = F.shape[-2]
    mag = np.abs(np.fft.rfft(np.asarray(F, dtype=np.float64), axis=-2))
    w = np.full(V // 2 + 1, 2.0)
    w[0] = 1.0
    if V % 2 == 0:
        w[-1] = 1.0
    return (mag * np.sqrt(w / V)[:, None]).astype(np.float32)


def rotation_invariant_descriptor(F: np.ndarray, *, dim: int = DESCRIPTOR_DIM, seed: int = 0) -> np.ndarray:
    """(dim,) float32 descriptor of one shape's view features F: (V, D) (or (n, V, D) -> (n, dim)), invariant
    under cyclic shifts of the views (see the module docstring); dim = 0 keeps the full (V//2+1) * D magnitudes.
    """
    F = np.asarray(F)
    if F.ndim not in (2, 3) or F.shape[-2] < 1:
        raise ValueError(f"view features must have shape (V, D) or (n, V, D), got {F.shape}")
    M = _dft_magnitudes(F)
    flat = M.reshape(M.shape[:-2] + (-1,))
    if not dim:
        return flat
    return flat @ projection_matrix(flat.shape[-1], int(dim), seed=int(seed))


def _check_descriptors(X: np.ndarray) -> np.ndarray:
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or len(X) < 1:
        raise ValueError(f"descriptors must have shape (N, d), got {X.shape}")
    if not np.all(np.isfinite(X)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(X), axis=1))[0])
        raise ValueError(f"descriptor of shape #{bad} is not finite: its view features are broken")
    return X


def principal_components(X: np.ndarray, *, dim: int = INDEX_DIM) -> np.ndarray:
    """(N, min(dim, d)) float32: the rows of X (N, d) centred and projected on their ``dim`` leading principal
    axes (eigenvectors of the d x d covariance, float64; each axis signed so that its largest entry is positive).
    X itself when d <= dim. Distances in the result approximate those of X (the dropped variance is small)."""
    X = _check_descriptors(X)
    if X.shape[1] <= dim:
        return X.astype(np.float32)
    Xc = X - X.mean(axis=0)
    _, vecs = np.linalg.eigh(Xc.T @ Xc)
    axes = vecs[:, ::-1][:, :dim]
    axes *= np.sign(axes[np.argmax(np.abs(axes), axis=0), np.arange(dim)])
    return (Xc @ axes).astype(np.float32)


def _knn_index(X: np.ndarray, k: int) -> np.ndarray:
    """(N, k) int64 indices of the k nearest rows of X (N, d) float32 to each row (itself included), -1 where an
    approximate index found fewer; faiss with one thread (deterministic)."""
    import faiss

    faiss.omp_set_num_threads(1)
    N, d = X.shape
    if N <= EXACT_MAX:
        index = faiss.IndexFlatL2(d)
    else:
        index = faiss.IndexHNSWFlat(d, HNSW_PARAMS["M"])
        index.hnsw.efConstruction = HNSW_PARAMS["efConstruction"]
    index.add(np.ascontiguousarray(X, dtype=np.float32))
    if N > EXACT_MAX:
        index.hnsw.efSearch = max(HNSW_PARAMS["efSearch"], k)
    return index.search(np.ascontiguousarray(X, dtype=np.float32), k)[1].astype(np.int64)


def nearest_pairs(X: np.ndarray, k: int) -> np.ndarray:
    """(<= N k, 2) int64 pairs (i, j): j among the k nearest other rows of X: (N, d) in Euclidean distance
    (``_knn_index``: exact up to EXACT_MAX rows, HNSW above)."""
    X = _check_descriptors(X)
    N = len(X)
    k = min(int(k), N - 1)
    if k <= 0:
        return np.zeros((0, 2), np.int64)
    idx = _knn_index(X.astype(np.float32), k + 1)              # includes i itself unless duplicated
    rows = np.repeat(np.arange(N), k + 1).reshape(N, k + 1)
    keep = (idx != rows) & (idx >= 0)
    # a row that did not find itself (exact duplicates) keeps its first k neighbours
    surplus = np.cumsum(keep, axis=1) > k
    keep &= ~surplus
    return np.stack([rows[keep], idx[keep]], axis=1)


def random_pairs(N: int, per_shape: int, *, seed: int = 0) -> np.ndarray:
    """(N per_shape, 2) int64 pairs (i, j != i), j uniform over the other shapes, from ``seed``."""
    if N < 2 or per_shape <= 0:
        return np.zeros((0, 2), np.int64)
    rng = np.random.default_rng(seed)
    i = np.repeat(np.arange(N), per_shape)
    j = (i + rng.integers(1, N, size=i.size)) % N
    return np.stack([i, j], axis=1).astype(np.int64)


def bridge_pairs(N: int, pairs: np.ndarray) -> np.ndarray:
    """(c - 1, 2) int64 pairs that connect the c connected components of the graph of ``pairs`` (N nodes): the
    smallest node of each component to the smallest node of the next one (components ordered by that node)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    A = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(N, N))
    n_comp, comp = connected_components(A, directed=False)
    if n_comp <= 1:
        return np.zeros((0, 2), np.int64)
    first = np.full(n_comp, N, np.int64)
    np.minimum.at(first, comp, np.arange(N))
    first = np.sort(first)
    return np.stack([first[:-1], first[1:]], axis=1)


def candidate_pairs(X: np.ndarray, *, k: int = 10, n_random: int = 2, seed: int = 0, self_pairs: bool = True,
                    index_dim: int = INDEX_DIM) -> tuple[np.ndarray, np.ndarray]:
    """The candidate graph of N shapes with descriptors X: (N, d).

    Returns (pairs (P, 2) int64 with pairs[:, 0] <= pairs[:, 1], sorted, unique; kind (P,) int8 of
    ``PAIR_KINDS``): the (i, i) pairs if ``self_pairs`` (C_ii gives each shape's symmetry), each shape's k nearest
    shapes in the descriptors' ``index_dim`` principal components (``nearest_pairs``), ``n_random`` random
    partners per shape (``random_pairs``; a pair that is also nearest counts as random, so the random pairs stay a
    uniform sample), and bridges until the graph is connected (``bridge_pairs``). Undirected: (i, j) and (j, i)
    are one pair. Same input -> same output.
    """
    X = _check_descriptors(X)
    N = len(X)
    found = [(nearest_pairs(principal_components(X, dim=index_dim), k), PAIR_KINDS["nearest"]),
             (random_pairs(N, n_random, seed=seed), PAIR_KINDS["random"])]
    off = np.concatenate([p for p, _ in found])
    found.append((bridge_pairs(N, off), PAIR_KINDS["bridge"]))
    if self_pairs:
        found.append((np.repeat(np.arange(N), 2).reshape(N, 2), PAIR_KINDS["self"]))
    pairs = np.concatenate([np.sort(p, axis=1) for p, _ in found])
    kinds = np.concatenate([np.full(len(p), kd, np.int8) for p, kd in found])
    key = pairs[:, 0] * N + pairs[:, 1]
    # unique pairs; a pair found as both nearest and random keeps the larger code ("random"; bridges join
    # different components and self pairs are only found once, so they never collide)
    order = np.lexsort((-kinds.astype(np.int64), key))
    key, kinds, pairs = key[order], kinds[order], pairs[order]
    first = np.concatenate([[True], key[1:] != key[:-1]])
    return pairs[first], kinds[first]


def complete_pairs(N: int) -> tuple[np.ndarray, np.ndarray]:
    """Every pair i < j of N shapes as (pairs (N(N-1)/2, 2) int64, kind (P,) int8 "complete"): the complete graph
    in the candidate layout (to compare with the candidate graph through the same stages)."""
    i, j = np.triu_indices(N, 1)
    return np.stack([i, j], axis=1).astype(np.int64), np.full(len(i), PAIR_KINDS["complete"], np.int8)
