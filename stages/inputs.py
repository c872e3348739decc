"""Input specs: what a task receives for each argument, as small typed values.

The planner builds them, the cache key is made of their ``key()`` (an upstream task's key stands for its
result, so big arrays are never hashed again), the executor orders tasks by their ``deps()``, and the worker
materialises them with ``load(store)``. Each kind is defined here once.

* :class:`ValueInput`: a dataset value (a path, a list of paths, or None), identified by its content digest;
* :class:`EntryInput`: the stored result of one upstream task;
* :class:`DictInput`: ``{item: value}`` of a per-item collection;
* :class:`StackInput`: the values of several items stacked into one array ``(n, ...)`` (pair tiles);
* :class:`PairsInput`: the whole ``(N, N, ...)`` matrix of a pair stage, assembled from its tiles;
* :class:`IndexPairsInput`: the ``(p, 2)`` local index pairs one task of a pair stage on a candidate graph
  computes (passed to the pair function as ``pairs``);
* :class:`SparsePairsInput`: the result of a pair stage on a candidate graph, ``{"names", "pairs", "values"}``
  (never an N x N array), assembled from its tasks.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Union

import numpy as np

if TYPE_CHECKING:
    from .store import Store


class InputError(ValueError):
    """A dataset item that cannot be used (e.g. a group with missing parts): the task that reads it fails."""


@dataclass(frozen=True)
class ValueInput:
    """A dataset value, passed as is. ``digest``: hash of the files' contents ("absent" for a missing optional).
    ``error``: why this item cannot be used (the task reading it fails with this message; a collection input
    leaves the item out)."""
    value: Any
    digest: str
    error: str = ""

    def key(self) -> Any:
        return self.digest

    def deps(self) -> list[str]:
        return []

    def load(self, store: "Store") -> Any:
        if self.error:
            raise InputError(self.error)
        return self.value


@dataclass(frozen=True)
class EntryInput:
    """The result of the upstream task whose key is ``entry``."""
    entry: str

    def key(self) -> Any:
        return self.entry

    def deps(self) -> list[str]:
        return [self.entry]

    def load(self, store: "Store") -> Any:
        return store.get(self.entry)  # the store keeps a per-process cache of decoded entries


@dataclass(frozen=True)
class DictInput:
    """A collection: item name -> input, loaded as ``{item: value}``."""
    items: dict[str, "InputSpec"]

    def key(self) -> Any:
        return {name: spec.key() for name, spec in self.items.items()}

    def deps(self) -> list[str]:
        return [k for spec in self.items.values() for k in spec.deps()]

    def load(self, store: "Store") -> dict[str, Any]:
        return {name: spec.load(store) for name, spec in self.items.items()}


@dataclass(frozen=True)
class StackInput:
    """Several items' values stacked along a new first axis: ``(len(parts), ...)``."""
    parts: tuple["InputSpec", ...]

    def key(self) -> Any:
        return [spec.key() for spec in self.parts]

    def deps(self) -> list[str]:
        return [k for spec in self.parts for k in spec.deps()]

    def load(self, store: "Store") -> np.ndarray:
        return np.stack([np.asarray(spec.load(store)) for spec in self.parts])


@dataclass(frozen=True)
class PairsInput:
    """A pair stage's result over all N items, from its upper-triangle tiles.

    names: the N item names in matrix order; blocks: ``(start, end)`` half-open ranges of ``names``;
    tiles: ``(block i, block j, task key)`` for i <= j; function: the registered pair function (its
    ``mirror`` turns an (a,b,...) block into the (b,a,...) block).
    """
    names: tuple[str, ...]
    blocks: tuple[tuple[int, int], ...]
    tiles: tuple[tuple[int, int, str], ...]
    function: str

    def key(self) -> Any:
        return {"names": list(self.names), "tiles": [list(t) for t in self.tiles], "mirror": self.function}

    def deps(self) -> list[str]:
        return [t[2] for t in self.tiles]

    def load(self, store: "Store", drop: frozenset[str] = frozenset()) -> dict:
        """{"names": [N names], "matrix": (N, N, ...) array}; lower tiles come from the function's mirror.

        drop: item names left out (items that failed upstream; their rows and columns are removed). A tile
        computed without some of its items is stored as ``{"partial_tile": {"rows", "cols"}, "block"}``
        (see :func:`partial_tile`)."""
        from . import registry

        mirror = registry.get(self.function).mirror
        flip = mirror if mirror is not None else (lambda b: np.swapaxes(b, 0, 1))
        n = len(self.names)
        matrix = None
        for bi, bj, key in self.tiles:
            stored = store.get(key)
            (s0, e0), (s1, e1) = self.blocks[bi], self.blocks[bj]
            rows, cols = np.arange(s0, e0), np.arange(s1, e1)
            if isinstance(stored, dict) and "partial_tile" in stored:
                rows, cols = rows[stored["partial_tile"]["rows"]], cols[stored["partial_tile"]["cols"]]
                if stored["block"] is None:
                    continue
                stored = stored["block"]
            block = np.asarray(stored)
            if matrix is None:
                matrix = np.full((n, n) + block.shape[2:], np.nan, dtype=np.result_type(block.dtype, np.float32)
                                 if drop else block.dtype)
            matrix[np.ix_(rows, cols)] = block
            if bi != bj:
                matrix[np.ix_(cols, rows)] = flip(block)
        if matrix is None:
            matrix = np.zeros((0, 0))
        keep = [i for i, name in enumerate(self.names) if name not in drop]
        if len(keep) < n and matrix.shape[0] == n:
            matrix = matrix[np.ix_(keep, keep)]
        return {"names": [self.names[i] for i in keep], "matrix": matrix}


def partial_tile(block: Any, rows: list[int], cols: list[int]) -> dict:
    """The stored form of a pair tile computed on some of its items only: ``block`` (a', b', ...) for the kept
    ``rows`` of A and ``cols`` of B (indices within the tile), or None when A or B kept nothing."""
    return {"partial_tile": {"rows": list(rows), "cols": list(cols)}, "block": block}


def partial_pairs(values: Any, kept: list[int]) -> dict:
    """The stored form of a candidate-pair task computed without some of its items: ``values`` (p', ...) for its
    pairs at positions ``kept`` (indices into the task's pairs), or None when no pair kept both items."""
    return {"partial_pairs": {"kept": list(kept)}, "values": values}


@dataclass(frozen=True, eq=False)
class IndexPairsInput:
    """The pairs one task of a candidate pair stage computes: ``pairs`` (p, 2) int64 (row of A, row of B),
    identified by ``digest`` (a hash of the array). Loaded as the array itself."""
    pairs: np.ndarray
    digest: str

    def key(self) -> Any:
        return self.digest

    def deps(self) -> list[str]:
        return []

    def load(self, store: "Store") -> np.ndarray:
        return self.pairs.copy()


@dataclass(frozen=True, eq=False)
class SparsePairsInput:
    """A pair stage's result on a candidate graph: one value per candidate pair, never an N x N array.

    names: the N item names (sorted); pairs: (P, 2) int64 global indices into ``names``, i < j, rows sorted;
    tasks: ``(start, end, task key)``: the task that computed rows start:end of ``pairs``, in row order;
    candidates: the key of the candidates stage's result (its left-out items are inherited);
    digest: a hash of ``pairs``; function: the registered pair function (its ``mirror`` gives the (j, i) values).
    """
    names: tuple[str, ...]
    pairs: np.ndarray
    tasks: tuple[tuple[int, int, str], ...]
    candidates: str
    digest: str
    function: str

    def key(self) -> Any:
        return {"names": list(self.names), "pairs": self.digest, "tasks": [list(t) for t in self.tasks],
                "candidates": self.candidates, "function": self.function}

    def deps(self) -> list[str]:
        return [self.candidates] + [t[2] for t in self.tasks]

    def load(self, store: "Store", drop: frozenset[str] = frozenset()) -> dict:
        """{"names": [n names], "pairs": (P', 2) int64 indices into names (i < j, sorted), "values": (P', ...)}.

        drop: item names left out (they failed upstream): removed from ``names`` with their pairs, and the
        remaining pairs renumbered. A task computed without some items is stored as
        ``{"partial_pairs": {"kept"}, "values"}`` (see :func:`partial_pairs`); its other pairs are left out."""
        computed = np.zeros(len(self.pairs), dtype=bool)
        parts: list[tuple[np.ndarray, np.ndarray]] = []   # (row indices into pairs, values)
        for start, end, key in self.tasks:
            stored, rows = store.get(key), np.arange(start, end)
            if isinstance(stored, dict) and "partial_pairs" in stored:
                rows = rows[np.asarray(stored["partial_pairs"]["kept"], dtype=np.int64)]
                stored = stored["values"]
                if stored is None:
                    continue
            parts.append((rows, np.asarray(stored)))
            computed[rows] = True
        keep_item = np.array([name not in drop for name in self.names], dtype=bool)
        keep_row = computed & keep_item[self.pairs[:, 0]] & keep_item[self.pairs[:, 1]] if len(self.pairs) else computed
        if parts:
            first = parts[0][1]
            values = np.zeros((len(self.pairs),) + first.shape[1:], dtype=first.dtype)
            for rows, v in parts:
                values[rows] = v
            values = values[keep_row]
        else:
            values = np.zeros((0,), dtype=np.float32)
        renumber = np.cumsum(keep_item) - 1
        pairs = renumber[self.pairs[keep_row]].astype(np.int64).reshape(-1, 2)
        return {"names": [n for n, k in zip(self.names, keep_item) if k], "pairs": pairs, "values": values}


InputSpec = Union[ValueInput, EntryInput, DictInput, StackInput, PairsInput, IndexPairsInput, SparsePairsInput]
