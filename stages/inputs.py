"""Input specs: what a task receives for each argument, as small typed values.

The planner builds them, the cache key is made of their ``key()`` (an upstream task's key stands for its
result, so big arrays are never hashed again), the executor orders tasks by their ``deps()``, and the worker
materialises them with ``load(store)``. Each kind is defined here once.

* :class:`ValueInput`: a dataset value (a path, a list of paths, or None), identified by its content digest;
* :class:`EntryInput`: the stored result of one upstream task;
* :class:`DictInput`: ``{item: value}`` of a per-item collection;
* :class:`StackInput`: the values of several items stacked into one array ``(n, ...)`` (pair tiles);
* :class:`PairsInput`: the whole ``(N, N, ...)`` matrix of a pair stage, assembled from its tiles.
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


InputSpec = Union[ValueInput, EntryInput, DictInput, StackInput, PairsInput]
