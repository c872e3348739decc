"""The content-addressed result store on a local disk: zarr v3 arrays plus an atomic JSON manifest per entry.

Layout under the cache root::

    objects/ab/<key>.zarr/     one zarr v3 array (<name>.zarr) per ndarray in the value
    objects/ab/<key>.files/    files a stage published (for writes_files stages)
    manifest/ab/<key>.json     written last, atomically: the entry is complete iff this exists and is valid
    runs/<pipeline-id>.json    the last run of each pipeline (keys, reasons, timings)
    filehash.json              (size, mtime) -> content hash cache for raw input files
    generated/<key>/           datasets written by generators
    tmp/                       half-written entries (never read; removed by gc)
    .stages-cache              the marker: written when the engine creates the cache (see Store.claim);
                               nothing is ever cleaned in a folder without it

A value is any tree of dicts (str keys), lists, numpy arrays and JSON scalars. Arrays go to zarr
(each entry is written by exactly one task, so there is one writer per chunk); the rest of the tree goes
to the manifest, which also records a checksum of every array and file so a corrupted entry is detected
when read and recomputed. The manifest itself carries a checksum over its canonical JSON (the inline values
included): a truncated, non-UTF-8, edited or foreign manifest counts as missing (one warning, then the entry
is recomputed), so ``has()`` and ``get()`` agree. The engine's small JSON tables (``filehash.json``,
``fingerprints.json``, ``runs/*.json``) are written and read the same way (``stages.checksums``).

A cache URL (``s3://bucket/prefix``, any fsspec protocol) keeps the entries on object storage instead
(``stages.cache.open_store(url)`` gives a :class:`stages.object_store.ObjectStore`, see there): same keys, same
checks.
"""
from __future__ import annotations

import json
import os
import shutil
import time
import uuid
from typing import Any

import numpy as np

from .cache_root import CACHE_MARKER, KEY_PATTERN, claim_folder
from .checksums import ABSENT, atomic_write_text, file_checksum, json_default, read_json_bytes
from .codec import copy_arrays, decode, encode, read_checked_arrays, write_arrays
from .errors import CorruptEntry, warn_once
from .manifest import FORMAT_VERSION, manifest_checksum, manifest_problem, same_content
from .read_cache import READ_CACHE


class Store:
    """Content-addressed entries under ``root`` (see module docstring)."""

    def __init__(self, root: str, warn: bool = True):
        """``warn``: print one warning per unreadable entry found (workers pass False: the client warns)."""
        self.root = os.path.abspath(root)
        self.warn = warn

    @property
    def location(self) -> str:
        """Where the entries live, as the user names it (a folder, or a URL for an object store): what a worker
        passes to ``open_store(...)``. ``root`` is always a local folder (temporary files, engine tables)."""
        return self.root

    def exists(self) -> bool:
        """True when the cache exists (so far only a planner looked at it otherwise)."""
        return os.path.isdir(self.root)

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

    # ownership ---------------------------------------------------------------------------------
    def is_marked(self) -> bool:
        """True when ``root`` carries the engine's cache marker (only then does it clean anything there)."""
        return os.path.isfile(os.path.join(self.root, CACHE_MARKER))

    def claim(self) -> None:
        """Make ``root`` the engine's cache: create it with its marker, or adopt a folder that holds only what
        the engine writes (a cache from before the marker existed). A read-only folder is left as it is.

        Raises:
            UserError: ``root`` is a file, or a folder with other content (e.g. ``cache: /tmp``): the engine
                neither writes nor cleans there.
        """
        if self.is_marked():
            return
        claim_folder(self.root)

    def writable(self) -> bool:
        """True when entries can be written under ``root``."""
        return os.access(self.root, os.W_OK | os.X_OK)

    def discard(self, path: str) -> None:
        """Remove a folder inside the cache (moved aside first, so a half-deleted folder is never seen)."""
        path = os.path.abspath(path)
        if os.path.commonpath([path, self.root]) != self.root or path == self.root:
            raise ValueError(f"refusing to remove {path}: it is not inside the cache {self.root}")
        trash = os.path.join(self.root, "tmp", "trash-" + uuid.uuid4().hex)
        os.makedirs(os.path.dirname(trash), exist_ok=True)
        try:
            os.rename(path, trash)
        except FileNotFoundError:
            return
        shutil.rmtree(trash, ignore_errors=True)

    # queries -----------------------------------------------------------------------------------
    def has(self, key: str) -> bool:
        """True when the entry is complete: its manifest is readable and matches its checksum, and every
        array folder and file it lists is present (file sizes checked; contents are checked on read)."""
        return self.complete(key) is not None

    def complete(self, key: str) -> dict | None:
        """The manifest of a complete entry (see :meth:`has`), else None: one look at the store answers both
        whether a result is there and what its manifest says (e.g. :func:`left_out_of`)."""
        manifest = self.manifest(key)
        if manifest is None:
            return None
        problem = self._missing_parts(key, manifest)
        if problem:
            self._warn_unusable(key, problem, manifest)
            return None
        return manifest

    def manifest(self, key: str) -> dict | None:
        """The entry's manifest, or None when it is missing or unusable (warned once, see :meth:`has`)."""
        path = self.manifest_path(key)
        try:
            st = os.stat(path)
        except OSError:
            return None
        hit = _MANIFESTS.get(path)
        if hit is not None and hit[0] == (st.st_size, st.st_mtime_ns):
            return hit[1]
        doc, problem = read_json_bytes(path)
        if doc is ABSENT:
            return None
        if problem is None:
            problem = manifest_problem(doc, key)
        if problem is not None:
            self._warn_unusable(key, f"its manifest {problem}")
            return None
        _MANIFESTS[path] = ((st.st_size, st.st_mtime_ns), doc)
        return doc

    def left_out(self, key: str) -> list[list[str]]:
        """The items a stored result was computed without (:func:`left_out_of` its manifest; empty when there is
        none)."""
        return left_out_of(self.manifest(key))

    def _missing_parts(self, key: str, manifest: dict) -> str | None:
        """What is wrong with the first array or file of the entry that is absent or has another size, else None."""
        for name in manifest["arrays"]:
            if not os.path.isdir(os.path.join(self.object_path(key), name + ".zarr")):
                return f"array {name} is missing"
        for rel, meta in manifest["files"].items():
            try:
                if os.path.getsize(os.path.join(self.files_path(key), rel)) != meta["size"]:
                    return f"published file {rel} was changed"
            except OSError:
                return f"published file {rel} is missing"
        return None

    def _warn_unusable(self, key: str, problem: str, manifest: dict | None = None) -> None:
        """Warn once that the entry ``key`` is unusable and why, naming its stage and item from ``manifest`` (else
        from the last manifest read of it, if any)."""
        if self.warn:
            info = ""
            if manifest is None:
                hit = _MANIFESTS.get(self.manifest_path(key))
                manifest = hit[1] if hit is not None else None
            if manifest is not None:
                meta = manifest.get("info", {})
                info = f" ({meta.get('stage', '')}{'[' + meta['label'] + ']' if meta.get('label') else ''})"
            warn_once(f"cache entry {self.manifest_path(key)}{info}: {problem}; treating it as missing and "
                      "recomputing it")

    def invalidate(self, key: str) -> None:
        """Forget an entry (its manifest), so the next run recomputes it."""
        READ_CACHE.drop(key)
        _MANIFESTS.pop(self.manifest_path(key), None)
        try:
            os.remove(self.manifest_path(key))
        except FileNotFoundError:
            pass

    # write -------------------------------------------------------------------------------------
    def put(self, key: str, value: Any, info: dict | None = None, files_dir: str | None = None) -> dict:
        """Store ``value`` (and the files in ``files_dir``) under ``key``; returns the manifest.

        Data is written to a private temporary folder and renamed into place; the manifest is written
        last and atomically, so a kill at any point leaves either a complete entry or none. Replacing an entry
        with other content (a forced recompute, a result now computed with items it left out) first removes
        the old manifest: a reader sees the old entry, then none, then the new one, never the old manifest
        over the new data.
        """
        arrays: dict[str, np.ndarray] = {}
        tree = encode(value, arrays)
        checksums = {}
        tmp = None
        if arrays:
            tmp = os.path.join(self.tmp_dir(), "data")
            os.makedirs(tmp)
            checksums = write_arrays({name: _local_zarr_store(os.path.join(tmp, name + ".zarr"))
                                      for name in arrays}, arrays)
        files = {}
        if files_dir and os.path.isdir(files_dir):
            for dirpath, _, filenames in os.walk(files_dir):
                for fn in filenames:
                    full = os.path.join(dirpath, fn)
                    files[os.path.relpath(full, files_dir)] = {"sha": file_checksum(full),
                                                               "size": os.path.getsize(full)}
        manifest = {"format": FORMAT_VERSION, "key": key, "created": time.time(), "tree": tree,
                    "arrays": checksums, "files": files, "info": info or {}}
        manifest = json.loads(json.dumps(manifest, default=json_default))  # the form a reader sees
        manifest["checksum"] = manifest_checksum(manifest)
        if self.manifest_exists(key):
            old = self._quiet_manifest(key)
            if old is None or not same_content(old, manifest):
                self.invalidate(key)  # the old entry is gone before its data is replaced
        if tmp is not None:
            self._move_into_place(tmp, self.object_path(key))
        elif os.path.exists(self.object_path(key)):  # arrays of an earlier entry under this key: not this one's
            self.discard(self.object_path(key))
        if files_dir and os.path.isdir(files_dir):
            self._move_into_place(files_dir, self.files_path(key))
        elif os.path.exists(self.files_path(key)):
            self.discard(self.files_path(key))
        _MANIFESTS.pop(self.manifest_path(key), None)
        atomic_write_text(self.manifest_path(key), json.dumps(manifest))
        return manifest

    def _quiet_manifest(self, key: str) -> dict | None:
        """:meth:`manifest` without the warning for an unusable one (the caller replaces it)."""
        warn, self.warn = self.warn, False
        try:
            return self.manifest(key)
        finally:
            self.warn = warn

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
        signature = (_stat_signature(self.manifest_path(key)), _files_signature(self.object_path(key)))
        cached = READ_CACHE.get(key)
        if cached is not None and cached[1] == signature:
            return copy_arrays(cached[0])
        manifest = self.manifest(key)
        if manifest is None:
            raise CorruptEntry(key, "manifest missing or unreadable")
        arrays = read_checked_arrays(key, manifest["arrays"], verify, lambda name: _local_zarr_store(
            os.path.join(self.object_path(key), name + ".zarr"), read_only=True))
        value = decode(manifest["tree"], arrays)
        READ_CACHE.put(key, (value, signature), sum(a.nbytes for a in arrays.values()))
        return copy_arrays(value)

    def verify_files(self, key: str) -> dict[str, str]:
        """{relative path: absolute path} of the entry's files, each checked against its checksum.

        Raises:
            CorruptEntry: the manifest is unusable, or a file is missing or changed.
        """
        manifest = self.manifest(key)
        if manifest is None:
            raise CorruptEntry(key, "manifest missing or unreadable")
        out = {}
        for rel, meta in manifest["files"].items():
            full = os.path.join(self.files_path(key), rel)
            if not os.path.isfile(full) or file_checksum(full) != meta["sha"]:
                raise CorruptEntry(key, f"published file {rel} is missing or changed")
            out[rel] = full
        return out

    # maintenance -------------------------------------------------------------------------------
    def all_keys(self) -> list[str]:
        base = os.path.join(self.root, "manifest")
        keys = []
        for dirpath, _, filenames in os.walk(base):
            keys.extend(fn[:-5] for fn in filenames if fn.endswith(".json") and KEY_PATTERN.match(fn[:-5]))
        return keys

    def remove(self, key: str) -> None:
        self.invalidate(key)
        shutil.rmtree(self.object_path(key), ignore_errors=True)
        shutil.rmtree(self.files_path(key), ignore_errors=True)

    def manifest_exists(self, key: str) -> bool:
        """True when a manifest file is there for ``key``, usable or not (``status`` says "corrupt" then)."""
        return os.path.exists(self.manifest_path(key))

    def entry_bytes(self, key: str) -> int:
        """Bytes of the entry's arrays and files (what ``gc`` frees by removing it)."""
        return sum(disk_usage(p) for p in (self.object_path(key), self.files_path(key)))

    def stale_writes(self) -> list[tuple[str, int]]:
        """(what, bytes) of data no manifest refers to, for ``gc``: none here (entries are renamed into place);
        an object store lists the writes of runs that lost a race or were killed."""
        return []

    def remove_stale(self, what: str) -> None:
        """Remove one item of :meth:`stale_writes`."""
        raise ValueError(f"{what}: a local cache has no stale writes")


def left_out_of(manifest: dict | None) -> list[list[str]]:
    """The items a stored result was computed without (``[[task key, failed task, item, why], ...]``, empty for a
    complete result or no manifest; see worker.run_task): recorded in the manifest's ``info``."""
    return list(manifest["info"].get("left_out", [])) if manifest is not None else []


def disk_usage(path: str) -> int:
    """Bytes of all files under ``path`` (0 if it does not exist)."""
    total = 0
    for dirpath, _, files in os.walk(path):
        for f in files:
            try:
                total += os.path.getsize(os.path.join(dirpath, f))
            except OSError:
                pass
    return total


# validated manifests of this process: path -> ((size, mtime_ns), manifest)
_MANIFESTS: dict[str, tuple[tuple[int, int], dict]] = {}


def _local_zarr_store(path: str, read_only: bool = False):
    """A zarr store of the folder ``path``. zarr is imported here, at the first entry with arrays: reading or
    writing an entry without arrays (a stage's metrics dict, most small results) never loads it, and the command
    that only reads metrics (``run``'s last step, ``results``) spares its import (docs/engine.md "Execution":
    ``results --json`` of the default pipeline 3.2-3.5 -> 1.65-1.9 s)."""
    import zarr
    return zarr.storage.LocalStore(path, read_only=read_only)


def _stat_signature(path: str) -> tuple | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns


def _files_signature(path: str) -> tuple:
    """(relative path, size, mtime_ns) of every file under ``path``: a cached read is reused only while the
    files on disk are untouched (so a corrupted or replaced chunk is read, and caught, again)."""
    sig = []
    for dirpath, _, files in os.walk(path):
        for f in files:
            st = os.stat(os.path.join(dirpath, f))
            sig.append((os.path.join(dirpath, f), st.st_size, st.st_mtime_ns))
    return tuple(sorted(sig))
