"""The content-addressed result store: zarr v3 arrays plus an atomic JSON manifest per entry.

Layout under the cache root::

    objects/ab/<key>.zarr/     one zarr v3 array (<name>.zarr) per ndarray in the value
    objects/ab/<key>.files/    files a stage published (for writes_files stages)
    manifest/ab/<key>.json     written last, atomically: the entry is complete iff this exists
    runs/<pipeline-id>.json    the last run of each pipeline (keys, reasons, timings)
    filehash.json              (size, mtime) -> content hash cache for raw input files
    generated/<key>/           datasets written by generators
    tmp/                       half-written entries (never read; removed by gc)

A value is any tree of dicts (str keys), lists, numpy arrays and JSON scalars. Arrays go to zarr
(each entry is written by exactly one task, so there is one writer per chunk); the rest of the tree goes
to the manifest, which also records a checksum of every array and file so a corrupted entry is detected
when read and recomputed.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
import uuid
from typing import Any

import numpy as np

from .errors import CorruptEntry

FORMAT_VERSION = 1
_CHUNK_BYTES = 32 * 2**20


def digest_bytes(data: bytes | memoryview) -> str:
    """A short hex content hash."""
    return hashlib.blake2b(data, digest_size=16).hexdigest()


def digest_json(obj: Any) -> str:
    """Hash of the canonical JSON of ``obj`` (sorted keys, no whitespace)."""
    return digest_bytes(canonical_json(obj).encode())


def canonical_json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=_json_default)


def _json_default(o: Any):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON-serializable: {type(o).__name__}")


def atomic_write_text(path: str, text: str) -> None:
    """Write ``text`` to ``path`` so readers see the old or the new content, never a mix."""
    path = os.path.abspath(path)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = f"{path}.{uuid.uuid4().hex}.tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)
    os.replace(tmp, path)


def array_checksum(a: np.ndarray) -> str:
    return digest_bytes(np.ascontiguousarray(a).view(np.uint8).reshape(-1).data if a.size else b"")


def file_checksum(path: str) -> str:
    h = hashlib.blake2b(digest_size=16)
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _encode(value: Any, arrays: dict[str, np.ndarray]) -> Any:
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
        return {"__dict__": {k: _encode(v, arrays) for k, v in value.items()}}
    if isinstance(value, (list, tuple)):
        return [_encode(v, arrays) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise TypeError(f"cannot store a value of type {type(value).__name__}")


def _decode(tree: Any, arrays: dict[str, np.ndarray]) -> Any:
    if isinstance(tree, dict):
        if "__array__" in tree:
            return arrays[tree["__array__"]]
        return {k: _decode(v, arrays) for k, v in tree["__dict__"].items()}
    if isinstance(tree, list):
        return [_decode(v, arrays) for v in tree]
    return tree


class Store:
    """Content-addressed entries under ``root`` (see module docstring)."""

    def __init__(self, root: str):
        self.root = os.path.abspath(root)

    # paths -------------------------------------------------------------------------------------
    def manifest_path(self, key: str) -> str:
        return os.path.join(self.root, "manifest", key[:2], key + ".json")

    def object_path(self, key: str) -> str:
        return os.path.join(self.root, "objects", key[:2], key + ".zarr")

    def files_path(self, key: str) -> str:
        return os.path.join(self.root, "objects", key[:2], key + ".files")

    def tmp_dir(self) -> str:
        path = os.path.join(self.root, "tmp", uuid.uuid4().hex)
        os.makedirs(path, exist_ok=True)
        return path

    # queries -----------------------------------------------------------------------------------
    def has(self, key: str) -> bool:
        """True when the entry is complete (its manifest exists)."""
        return os.path.exists(self.manifest_path(key))

    def manifest(self, key: str) -> dict | None:
        try:
            with open(self.manifest_path(key), encoding="utf-8") as fh:
                return json.load(fh)
        except FileNotFoundError:
            return None
        except json.JSONDecodeError:
            return None

    def invalidate(self, key: str) -> None:
        """Forget an entry (its manifest), so the next run recomputes it."""
        _READ_CACHE.drop(key)
        try:
            os.remove(self.manifest_path(key))
        except FileNotFoundError:
            pass

    # write -------------------------------------------------------------------------------------
    def put(self, key: str, value: Any, info: dict | None = None, files_dir: str | None = None) -> dict:
        """Store ``value`` (and the files in ``files_dir``) under ``key``; returns the manifest.

        Data is written to a private temporary folder and renamed into place; the manifest is written
        last and atomically, so a kill at any point leaves either a complete entry or none.
        """
        import zarr

        arrays: dict[str, np.ndarray] = {}
        tree = _encode(value, arrays)
        checksums = {}
        if arrays:
            tmp = os.path.join(self.tmp_dir(), "data")
            os.makedirs(tmp)
            for name, arr in arrays.items():
                arr = np.ascontiguousarray(arr)
                store = zarr.storage.LocalStore(os.path.join(tmp, name + ".zarr"))
                if arr.size:
                    zarr.create_array(store=store, data=arr, chunks=_chunks_for(arr),
                                      fill_value=_fill_value(arr.dtype))
                else:
                    zarr.create_array(store=store, shape=arr.shape, dtype=arr.dtype,
                                      chunks=tuple(max(1, c) for c in arr.shape), fill_value=_fill_value(arr.dtype))
                checksums[name] = {"sha": array_checksum(arr), "shape": list(arr.shape), "dtype": str(arr.dtype)}
            self._move_into_place(tmp, self.object_path(key))
        files = {}
        if files_dir and os.path.isdir(files_dir):
            for dirpath, _, filenames in os.walk(files_dir):
                for fn in filenames:
                    full = os.path.join(dirpath, fn)
                    files[os.path.relpath(full, files_dir)] = file_checksum(full)
            self._move_into_place(files_dir, self.files_path(key))
        manifest = {"format": FORMAT_VERSION, "key": key, "created": time.time(), "tree": tree,
                    "arrays": checksums, "files": files, "info": info or {}}
        atomic_write_text(self.manifest_path(key), json.dumps(manifest, default=_json_default))
        return manifest

    def _move_into_place(self, src: str, dst: str) -> None:
        """Rename ``src`` to ``dst``, first moving aside any stale ``dst`` (from an invalidated entry)."""
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        if os.path.exists(dst):
            trash = os.path.join(self.root, "tmp", "trash-" + uuid.uuid4().hex)
            try:
                os.rename(dst, trash)
                shutil.rmtree(trash, ignore_errors=True)
            except OSError:
                pass
        try:
            os.rename(src, dst)
        except OSError:
            if not os.path.exists(dst):
                raise
        shutil.rmtree(os.path.dirname(src) if os.path.basename(src) == "data" else src, ignore_errors=True)

    # read --------------------------------------------------------------------------------------
    def get(self, key: str, verify: bool = True) -> Any:
        """Load an entry's value; with ``verify`` every array is checked against its checksum.

        Raises:
            CorruptEntry: missing data or checksum mismatch (the caller recomputes the entry).
        """
        import zarr

        signature = _files_signature(self.object_path(key))
        cached = _READ_CACHE.get(key)
        if cached is not None and cached[1] == signature:
            return _copy_arrays(cached[0])
        manifest = self.manifest(key)
        if manifest is None:
            raise CorruptEntry(key, "manifest missing or unreadable")
        arrays = {}
        for name, meta in manifest["arrays"].items():
            try:
                arr = np.asarray(zarr.open_array(store=zarr.storage.LocalStore(
                    os.path.join(self.object_path(key), name + ".zarr"), read_only=True), mode="r")[...])
            except Exception as exc:  # missing chunk files, bad metadata, decompression errors
                raise CorruptEntry(key, f"array {name}: {type(exc).__name__}: {exc}") from exc
            if list(arr.shape) != meta["shape"] or (verify and array_checksum(arr) != meta["sha"]):
                raise CorruptEntry(key, f"array {name} does not match its checksum")
            arrays[name] = arr
        value = _decode(manifest["tree"], arrays)
        _READ_CACHE.put(key, (value, signature), sum(a.nbytes for a in arrays.values()))
        return _copy_arrays(value)

    def verify_files(self, key: str) -> dict[str, str]:
        """{relative path: absolute path} of the entry's files, each checked against its checksum."""
        manifest = self.manifest(key) or {}
        out = {}
        for rel, sha in manifest.get("files", {}).items():
            full = os.path.join(self.files_path(key), rel)
            if not os.path.isfile(full) or file_checksum(full) != sha:
                raise CorruptEntry(key, f"published file {rel} is missing or changed")
            out[rel] = full
        return out

    # maintenance -------------------------------------------------------------------------------
    def all_keys(self) -> list[str]:
        base = os.path.join(self.root, "manifest")
        keys = []
        for dirpath, _, filenames in os.walk(base):
            keys.extend(fn[:-5] for fn in filenames if fn.endswith(".json"))
        return keys

    def remove(self, key: str) -> None:
        self.invalidate(key)
        shutil.rmtree(self.object_path(key), ignore_errors=True)
        shutil.rmtree(self.files_path(key), ignore_errors=True)


def _files_signature(path: str) -> tuple:
    """(relative path, size, mtime_ns) of every file under ``path``: a cached read is reused only while the
    files on disk are untouched (so a corrupted or replaced chunk is read, and caught, again)."""
    sig = []
    for dirpath, _, files in os.walk(path):
        for f in files:
            st = os.stat(os.path.join(dirpath, f))
            sig.append((os.path.join(dirpath, f), st.st_size, st.st_mtime_ns))
    return tuple(sorted(sig))


class _LRU:
    """Per-process cache of decoded entries (content-addressed, so never stale), bounded in bytes.

    Pair tiles read the same per-item entries many times on one worker; this avoids re-reading them.
    Size: STAGES_READ_CACHE_MB (default 1024).
    """

    def __init__(self):
        from collections import OrderedDict
        self.items: "OrderedDict[str, tuple[Any, int]]" = OrderedDict()
        self.bytes = 0
        self.limit = int(os.environ.get("STAGES_READ_CACHE_MB", "1024")) * 2**20

    def get(self, key: str):
        hit = self.items.get(key)
        if hit is None:
            return None
        self.items.move_to_end(key)
        return hit[0]

    def put(self, key: str, value: Any, nbytes: int) -> None:
        if nbytes > self.limit // 4:
            return
        self.items[key] = (value, nbytes)
        self.bytes += nbytes
        while self.bytes > self.limit and self.items:
            _, (_, b) = self.items.popitem(last=False)
            self.bytes -= b

    def drop(self, key: str) -> None:
        hit = self.items.pop(key, None)
        if hit is not None:
            self.bytes -= hit[1]


_READ_CACHE = _LRU()


def _copy_arrays(value: Any) -> Any:
    """A copy of the array leaves (callers may modify what they get), sharing nothing mutable."""
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, dict):
        return {k: _copy_arrays(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_copy_arrays(v) for v in value]
    return value


def _fill_value(dtype: np.dtype):
    dtype = np.dtype(dtype)
    if dtype.kind == "f":
        return float("nan")
    if dtype.kind == "c":
        return complex(float("nan"), float("nan"))
    if dtype.kind == "b":
        return False
    return 0


def _chunks_for(arr: np.ndarray) -> tuple[int, ...]:
    """Whole array as one chunk up to 32 MiB, else split along the first axis."""
    if arr.ndim == 0:
        return ()
    shape = [max(1, s) for s in arr.shape]
    row_bytes = max(1, arr.itemsize * int(np.prod(shape[1:])))
    rows = max(1, min(shape[0], _CHUNK_BYTES // row_bytes))
    return (rows, *shape[1:])
