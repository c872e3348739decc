"""The value codec: a stored value (dicts, lists, numpy arrays, JSON scalars, ``Skipped``) as a JSON tree plus zarr
arrays."""
from __future__ import annotations

from typing import Any

import numpy as np

from .checksums import array_checksum
from .errors import CorruptEntry
from .skipped import Skipped

CHUNK_BYTES = 32 * 2**20


def encode(value: Any, arrays: dict[str, np.ndarray]) -> Any:
    """The JSON tree of ``value``; each array in it is added to ``arrays`` as ``aN`` and named in the tree.

    Raises:
        TypeError: a value the store cannot keep (object arrays, non-string dict keys, other types).
    """
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return value.item()
    if isinstance(value, np.ndarray):
        if value.dtype == object:
            raise TypeError("object arrays cannot be stored; return numeric arrays, lists or dicts")
        name = f"a{len(arrays)}"
        arrays[name] = value
        return {"__array__": name}
    if isinstance(value, dict):
        for k in value:
            if not isinstance(k, str):
                raise TypeError(f"dict keys must be strings to be stored, got {type(k).__name__}")
        return {"__dict__": {k: encode(v, arrays) for k, v in value.items()}}
    if isinstance(value, (list, tuple)):
        return [encode(v, arrays) for v in value]
    if isinstance(value, Skipped):
        return {"__skipped__": value.why}
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise TypeError(f"cannot store a value of type {type(value).__name__}")


def decode(tree: Any, arrays: dict[str, np.ndarray]) -> Any:
    """The value :func:`encode` turned into ``tree`` (with its ``arrays``)."""
    if isinstance(tree, dict):
        if "__array__" in tree:
            return arrays[tree["__array__"]]
        if "__skipped__" in tree:
            return Skipped(tree["__skipped__"])
        return {k: decode(v, arrays) for k, v in tree["__dict__"].items()}
    if isinstance(tree, list):
        return [decode(v, arrays) for v in tree]
    return tree


def copy_arrays(value: Any) -> Any:
    """A copy of the array leaves (callers may modify what they get), sharing nothing mutable."""
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, dict):
        return {k: copy_arrays(v) for k, v in value.items()}
    if isinstance(value, list):
        return [copy_arrays(v) for v in value]
    return value


def write_arrays(stores: dict[str, Any], arrays: dict[str, np.ndarray]) -> dict[str, dict]:
    """Write each array ``arrays[name]`` as a zarr array into the zarr store ``stores[name]``, all at once (one
    pass of zarr's event loop instead of one round trip per array: an entry holds up to a few dozen small
    arrays); returns {name: manifest record ({"sha", "shape", "dtype"})}."""
    import zarr.core.array as zarr_array

    contiguous = {name: np.ascontiguousarray(arr) for name, arr in arrays.items()}

    def create(name: str):
        arr = contiguous[name]
        if arr.size:
            return zarr_array.create_array(stores[name], data=arr, chunks=chunks_for(arr),
                                           fill_value=fill_value(arr.dtype))
        return zarr_array.create_array(stores[name], shape=arr.shape, dtype=arr.dtype,
                                       chunks=tuple(max(1, c) for c in arr.shape), fill_value=fill_value(arr.dtype))

    for failure in _run_together([create(name) for name in contiguous]):
        if isinstance(failure, Exception):   # raised as one write alone raised it: the entry is not stored
            raise failure
    return {name: {"sha": array_checksum(arr), "shape": list(arr.shape), "dtype": str(arr.dtype)}
            for name, arr in contiguous.items()}


def _run_together(coroutines: list) -> list:
    """The results of zarr coroutines run concurrently on zarr's event loop (an exception is returned in place of
    its coroutine's result; the others still finish)."""
    import asyncio

    from zarr.core.sync import sync

    async def gather():
        return await asyncio.gather(*coroutines, return_exceptions=True)

    results = sync(gather()) if coroutines else []
    for r in results:
        if isinstance(r, BaseException) and not isinstance(r, Exception):
            raise r
    return results


def read_checked_arrays(key: str, arrays_meta: dict, verify: bool, open_store,
                        zarr_format: int | None = None) -> dict[str, np.ndarray]:
    """{name: array} of an entry's arrays, each read from ``open_store(name)`` (a zarr store) and checked
    against its manifest record ``arrays_meta[name]`` ({"shape", "sha"}; the checksum only when ``verify``);
    ``zarr_format`` None lets zarr detect it (an object store passes 3 to save the probing requests).

    Raises:
        CorruptEntry: an array is missing, unreadable, or does not match its record.
    """
    if not arrays_meta:                  # an entry without arrays: zarr is not even imported
        return {}
    import zarr.api.asynchronous as zarr_async

    async def read(store) -> np.ndarray:
        array = await zarr_async.open_array(store=store, mode="r", zarr_format=zarr_format)
        return np.asarray(await array.getitem(...))

    names = list(arrays_meta)
    stores = []
    for name in names:
        try:
            stores.append(open_store(name))
        except Exception as exc:  # noqa: BLE001 -- e.g. an object store that cannot be reached
            raise CorruptEntry(key, f"array {name}: {type(exc).__name__}: {exc}") from exc
    arrays = {}
    for name, arr in zip(names, _run_together([read(store) for store in stores])):   # all read at once
        meta = arrays_meta[name]
        if isinstance(arr, Exception):  # missing objects or chunk files, bad metadata, decompression errors
            raise CorruptEntry(key, f"array {name}: {type(arr).__name__}: {arr}") from arr
        if list(arr.shape) != meta["shape"] or (verify and array_checksum(arr) != meta["sha"]):
            raise CorruptEntry(key, f"array {name} does not match its checksum")
        arrays[name] = arr
    return arrays


def fill_value(dtype: np.dtype):
    """The zarr fill value of ``dtype`` (NaN for floats and complex numbers)."""
    dtype = np.dtype(dtype)
    if dtype.kind == "f":
        return float("nan")
    if dtype.kind == "c":
        return complex(float("nan"), float("nan"))
    if dtype.kind == "b":
        return False
    return 0


def chunks_for(arr: np.ndarray) -> tuple[int, ...]:
    """Whole array as one chunk up to 32 MiB, else split along the first axis."""
    if arr.ndim == 0:
        return ()
    shape = [max(1, s) for s in arr.shape]
    row_bytes = max(1, arr.itemsize * int(np.prod(shape[1:])))
    rows = max(1, min(shape[0], CHUNK_BYTES // row_bytes))
    return (rows, *shape[1:])
