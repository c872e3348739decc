"""Generic pairwise MRF on n nodes x L labels, maximized by Leordeanu & Hebert's spectral relaxation + climbing.

Energy (MAXIMIZED)::

    E(x) = sum_i U[i, x_i] + sum_{i<j} W[i, j, x_i, x_j],      x_i in 0..L-1,  W[i, i] = 0.

With X the (n, L) one-hot matrix of a labeling and M the (nL x nL) matrix M[(i,a),(j,b)] = W[i,j,a,b],
E(x) = X.M.X / 2 + U.X  (M symmetric because W[i,j,a,b] == W[j,i,b,a], zero diagonal blocks).

Pairwise operator protocol (anything with these members works with every solver here):

- ``n_nodes: int``, ``n_labels: int``
- ``matvec(X: (n,L)) -> (n,L)``: Y[i,a] = sum_j sum_b W[i,j,a,b] X[j,b]  (i.e. M @ X.ravel()).
- ``column(j, b) -> (n,L)``: W[:, j, :, b], the change of every node's local gains when node j takes label b.
- optional ``block_max() -> (n,n)``: max_{a,b} W[i,j,a,b] (used for the trivial upper bound).

``DensePairwise`` stores W explicitly; ``corr_core.alignment.circulant.CirculantPairwise`` implements the same protocol
with FFTs for the rotation-alignment problem.

Solver (``solve_lh``), after Leordeanu & Hebert, "Efficient MAP approximation for dense energy functions",
ICML 2006:

1. relaxed optimum: start from x_i = 1/sqrt(L) for every node, iterate x <- M x + U and renormalize each
   node's label vector to unit L2 norm, until max |x_new - x| < tol (or max_iter). The fixed point is a
   stationary point of x.M.x/2 + U.x subject to ||x_i||_2 = 1 (a set that contains every discrete labeling).
2. map each node's vector onto the simplex: clip negatives to 0 and divide by the L1 norm.
3. climbing: start from the argmax label of each node's simplex vector, then coordinate ascent (set one node
   at a time to its best label given the others, sweeping nodes 0..n-1 until a full sweep changes nothing).
   Local gains G = U + M X are updated incrementally with ``column``; every accepted move strictly raises E.

All energies are float64.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse.linalg import LinearOperator, eigsh

__all__ = [
    "DensePairwise",
    "LHResult",
    "energy",
    "local_gains",
    "climb",
    "icm",
    "solve_lh",
    "random_labels",
    "best_of_random_restarts",
    "leading_eigenvalue",
    "upper_bound",
]


class DensePairwise:
    """Explicit pairwise potentials W: (n, n, L, L) float, W[i,j,a,b] == W[j,i,b,a]; diagonal blocks zeroed.

    Raises ValueError if W is not symmetric in that sense (relative tolerance 1e-6).
    """

    def __init__(self, W: np.ndarray, check_symmetry: bool = True):
        W = np.array(W, dtype=np.float64, copy=True)
        if W.ndim != 4 or W.shape[0] != W.shape[1] or W.shape[2] != W.shape[3]:
            raise ValueError(f"W must have shape (n, n, L, L), got {W.shape}")
        n, _, L, _ = W.shape
        W[np.arange(n), np.arange(n)] = 0.0
        if check_symmetry:
            WT = W.transpose(1, 0, 3, 2)
            scale = max(1.0, float(np.abs(W).max(initial=0.0)))
            if not np.allclose(W, WT, rtol=1e-6, atol=1e-9 * scale):
                raise ValueError("W must satisfy W[i,j,a,b] == W[j,i,b,a]")
        self.W = W
        self.n_nodes = n
        self.n_labels = L
        # M[(i,a),(j,b)] = W[i,j,a,b]: one (nL x nL) matrix for the matvec
        self._M = W.transpose(0, 2, 1, 3).reshape(n * L, n * L)

    def matvec(self, X: np.ndarray) -> np.ndarray:
        """Y: (n,L) with Y[i,a] = sum_{j,b} W[i,j,a,b] X[j,b]."""
        X = np.asarray(X, dtype=np.float64)
        return (self._M @ X.reshape(-1)).reshape(self.n_nodes, self.n_labels)

    def column(self, j: int, b: int) -> np.ndarray:
        """W[:, j, :, b]: (n, L)."""
        return self.W[:, j, :, b]

    def block_max(self) -> np.ndarray:
        """(n, n): max_{a,b} W[i,j,a,b] (0 on the diagonal)."""
        return self.W.max(axis=(2, 3))

    def as_matrix(self) -> np.ndarray:
        """The explicit (nL x nL) matrix M[(i,a),(j,b)] = W[i,j,a,b] (a view; do not modify)."""
        return self._M


@dataclass
class LHResult:
    """Result of ``solve_lh``.

    labels: (n,) int, final discrete labeling after climbing.
    energy: E(labels).
    relaxed: (n, L) float, the relaxed optimum of step 1 (each row unit L2 norm).
    relaxed_value: x.M.x/2 + U.x at ``relaxed`` (the quantity step 1 increases). This is a local value of the
        relaxation, NOT guaranteed to bound E from above (and for dense non-negative W it can exceed max E
        many times over, since unit-L2 rows spread mass over all labels); use ``upper_bound`` for a bound.
    simplex_value: the same expression at the simplex rows (step 2), i.e. the expected energy when each node
        draws its label independently from its simplex row.
    upper_bound: a valid upper bound on E over all discrete labelings (see ``upper_bound()``), or nan if
        ``compute_bound=False``.
    iterations: number of step-1 iterations.
    converged: whether step 1 reached ``tol``.
    energy_before_climb: E(argmax of the simplex vectors), the labeling climbing starts from.
    climb_moves: number of single-node moves accepted by the climbing.
    """

    labels: np.ndarray
    energy: float
    relaxed: np.ndarray
    relaxed_value: float
    simplex_value: float
    upper_bound: float
    iterations: int
    converged: bool
    energy_before_climb: float
    climb_moves: int


def _one_hot(labels: np.ndarray, L: int) -> np.ndarray:
    X = np.zeros((labels.shape[0], L), dtype=np.float64)
    X[np.arange(labels.shape[0]), labels] = 1.0
    return X


def _check_problem(pairwise, unary: np.ndarray) -> np.ndarray:
    unary = np.asarray(unary, dtype=np.float64)
    if unary.shape != (pairwise.n_nodes, pairwise.n_labels):
        raise ValueError(f"unary must be (n, L) = {(pairwise.n_nodes, pairwise.n_labels)}, got {unary.shape}")
    return unary


def local_gains(pairwise, unary: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """G: (n, L), G[i, a] = U[i, a] + sum_j W[i, j, a, x_j]: the energy contribution of node i taking label a
    with every other node fixed (W[i,i] = 0, so G[i] does not depend on x_i)."""
    unary = _check_problem(pairwise, unary)
    labels = np.asarray(labels, dtype=np.int64)
    return unary + pairwise.matvec(_one_hot(labels, pairwise.n_labels))


def energy(pairwise, unary: np.ndarray, labels: np.ndarray) -> float:
    """E(labels) = sum_i U[i, x_i] + sum_{i<j} W[i, j, x_i, x_j]; labels: (n,) int in 0..L-1."""
    unary = _check_problem(pairwise, unary)
    labels = np.asarray(labels, dtype=np.int64)
    X = _one_hot(labels, pairwise.n_labels)
    return float(np.sum(unary * X) + 0.5 * np.sum(X * pairwise.matvec(X)))


def climb(pairwise, unary: np.ndarray, labels0: np.ndarray, *, max_sweeps: int = 1000) -> tuple[np.ndarray, int]:
    """Coordinate ascent from labels0: sweep nodes 0..n-1, move a node to its best label given the others if
    that raises E by more than a rounding-level epsilon; stop after a sweep without moves.

    Returns (labels (n,) int, number of accepted moves). Never lowers E; the result is a local maximum with
    respect to single-node changes ("ICM" / iterated conditional modes).
    """
    unary = _check_problem(pairwise, unary)
    labels = np.array(labels0, dtype=np.int64, copy=True)
    n = pairwise.n_nodes
    moves = 0
    for _ in range(max_sweeps):
        # recompute the gains once per sweep so incremental rounding errors cannot accumulate
        G = local_gains(pairwise, unary, labels)
        eps = 1e-12 * max(1.0, float(np.abs(G).max()))
        changed = False
        for i in range(n):
            a_new = int(np.argmax(G[i]))
            a_old = int(labels[i])
            if G[i, a_new] > G[i, a_old] + eps:
                G += pairwise.column(i, a_new) - pairwise.column(i, a_old)
                labels[i] = a_new
                moves += 1
                changed = True
        if not changed:
            break
    return labels, moves


def icm(pairwise, unary: np.ndarray, labels0: np.ndarray) -> np.ndarray:
    """Iterated conditional modes from labels0 (same coordinate ascent as LH's climbing): labels (n,) int."""
    return climb(pairwise, unary, labels0)[0]


def random_labels(n: int, L: int, rng: np.random.Generator | int | None = None) -> np.ndarray:
    """(n,) int labels drawn uniformly from 0..L-1."""
    rng = np.random.default_rng(rng)
    return rng.integers(0, L, size=n)


def best_of_random_restarts(pairwise, unary: np.ndarray, n_restarts: int, *, seed: int = 0) -> tuple[np.ndarray, float]:
    """ICM from ``n_restarts`` uniformly random labelings; returns (best labels (n,) int, its energy)."""
    rng = np.random.default_rng(seed)
    best_labels, best_e = None, -np.inf
    for _ in range(n_restarts):
        labels = icm(pairwise, unary, random_labels(pairwise.n_nodes, pairwise.n_labels, rng))
        e = energy(pairwise, unary, labels)
        if e > best_e:
            best_labels, best_e = labels, e
    return best_labels, best_e


def leading_eigenvalue(pairwise) -> float:
    """Largest eigenvalue of the symmetric (nL x nL) matrix M, using only ``matvec`` (Lanczos; a dense
    eigensolve for nL <= 400)."""
    n, L = pairwise.n_nodes, pairwise.n_labels
    N = n * L
    if N <= 400:
        M = np.column_stack([pairwise.matvec(e.reshape(n, L)).reshape(-1) for e in np.eye(N)])
        return float(np.linalg.eigvalsh(0.5 * (M + M.T))[-1])
    op = LinearOperator((N, N), matvec=lambda v: pairwise.matvec(np.asarray(v).reshape(n, L)).reshape(-1),
                        dtype=np.float64)
    v0 = np.full(N, 1.0 / np.sqrt(N))
    return float(eigsh(op, k=1, which="LA", tol=1e-10, v0=v0, return_eigenvectors=False)[0])


def upper_bound(pairwise, unary: np.ndarray, lambda_max: float | None = None) -> float:
    """A valid upper bound on max_x E(x) over discrete labelings:

        sum_i max_a U[i,a] + min( n * lambda_max(M) / 2,  sum_{i<j} max_{a,b} W[i,j,a,b] ).

    The first pairwise term holds because a one-hot X has ||X||^2 = n (Rayleigh quotient); the second is the
    trivial per-pair bound (used only if the operator has ``block_max``). lambda_max comes from Lanczos, whose
    Ritz value can sit a hair below the true value; 1e-9 relative slack is added.
    """
    unary = _check_problem(pairwise, unary)
    if lambda_max is None:
        lambda_max = leading_eigenvalue(pairwise)
    lam = lambda_max + 1e-9 * max(1.0, abs(lambda_max))
    pair_bound = pairwise.n_nodes * lam / 2.0
    if hasattr(pairwise, "block_max"):
        B = pairwise.block_max()
        pair_bound = min(pair_bound, float(np.triu(B, 1).sum()))
    return float(unary.max(axis=1).sum() + pair_bound)


def _normalize_rows_l2(X: np.ndarray) -> np.ndarray:
    norms = np.linalg.norm(X, axis=1, keepdims=True)
    L = X.shape[1]
    return np.where(norms > 0, X / np.where(norms > 0, norms, 1.0), 1.0 / np.sqrt(L))


def _rows_to_simplex(X: np.ndarray) -> np.ndarray:
    """Clip negatives to 0 and L1-normalize each row (uniform row if all entries were <= 0)."""
    P = np.clip(X, 0.0, None)
    s = P.sum(axis=1, keepdims=True)
    return np.where(s > 0, P / np.where(s > 0, s, 1.0), 1.0 / X.shape[1])


def solve_lh(pairwise, unary: np.ndarray, *, max_iter: int = 1000, tol: float = 1e-9,
             compute_bound: bool = True) -> LHResult:
    """Leordeanu & Hebert (ICML 2006) MAP approximation for the MRF (pairwise operator, unary (n,L)).

    Steps (see module docstring): relaxed fixed point of x <- normalize_rows_L2(M x + U) starting from uniform
    rows; L1/simplex mapping; climbing (coordinate ascent) from the argmax of each simplex row.
    ``compute_bound=True`` also computes the spectral upper bound (a Lanczos run on M).
    """
    unary = _check_problem(pairwise, unary)
    n, L = pairwise.n_nodes, pairwise.n_labels
    x = np.full((n, L), 1.0 / np.sqrt(L))
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        x_new = _normalize_rows_l2(pairwise.matvec(x) + unary)
        delta = float(np.abs(x_new - x).max())
        x = x_new
        if delta < tol:
            converged = True
            break
    relaxed_value = float(0.5 * np.sum(x * pairwise.matvec(x)) + np.sum(unary * x))
    simplex = _rows_to_simplex(x)
    simplex_value = float(0.5 * np.sum(simplex * pairwise.matvec(simplex)) + np.sum(unary * simplex))
    start = np.argmax(simplex, axis=1).astype(np.int64)
    e_start = energy(pairwise, unary, start)
    labels, moves = climb(pairwise, unary, start)
    bound = upper_bound(pairwise, unary) if compute_bound else float("nan")
    return LHResult(labels=labels, energy=energy(pairwise, unary, labels), relaxed=x,
                    relaxed_value=relaxed_value, simplex_value=simplex_value, upper_bound=bound, iterations=it, converged=converged,
                    energy_before_climb=e_start, climb_moves=moves)
