"""The content-addressed result store: zarr v3 arrays plus an atomic JSON manifest per entry.

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
``fingerprints.json``, ``runs/*.json``) are written and read the same way (:func:`write_checked_json`,
:func:`read_checked_json`).

A cache URL (``s3://bucket/prefix``, any fsspec protocol) keeps the entries on object storage instead
(``Store(url)`` is then a :class:`stages.object_store.ObjectStore`, see there): same keys, same checks.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import time
import uuid
from typing import Any

import numpy as np

from .errors import CorruptEntry, UserError, warn_once

FORMAT_VERSION = 2
_MANIFEST_FIELDS = ("format", "key", "created", "tree", "arrays", "files", "info")
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
    if os.path.isdir(path):
        raise IsADirectoryError(21, "is a folder, not a file", path)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = f"{path}.{uuid.uuid4().hex}.tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):  # the write or the rename failed: leave nothing behind
            os.remove(tmp)


_ABSENT = object()


def _read_json_bytes(path: str) -> tuple[Any, str | None]:
    """(parsed JSON, None), or (None, why it is unusable); (_ABSENT, None) when the file does not exist."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except FileNotFoundError:
        return _ABSENT, None
    except OSError as exc:
        return None, f"cannot be read ({exc.strerror or exc})"
    try:
        return json.loads(data.decode("utf-8")), None
    except UnicodeDecodeError:
        return None, "is not UTF-8 text (overwritten or damaged)"
    except ValueError:
        return None, "is not valid JSON (truncated or edited)"
    except RecursionError:  # e.g. '[' * 200000: damaged, like a truncated file (never a traceback)
        return None, _TOO_DEEP


_TOO_DEEP = "is nested too deeply to be read (damaged or not written by the engine)"


def write_checked_json(path: str, obj: Any) -> None:
    """Write ``obj`` atomically as ``{"checksum": ..., "data": obj}`` (see :func:`read_checked_json`)."""
    data = json.loads(json.dumps(obj, default=_json_default))
    atomic_write_text(path, json.dumps({"checksum": digest_json(data), "data": data}))


def read_checked_json(path: str, what: str, default: Any = None, kind: type | None = dict,
                      warn: bool = True) -> Any:
    """The ``data`` written by :func:`write_checked_json`, or ``default`` when the file is missing or unusable.

    Unusable (truncated, not UTF-8, not JSON, checksum mismatch, not a ``kind``) means: warn once naming the
    file and what happens (``what``, e.g. "rebuilding it"), and return ``default``; never raise.
    """
    doc, problem = _read_json_bytes(path)
    if doc is _ABSENT:
        return default
    if problem is None:
        try:
            if not isinstance(doc, dict) or set(doc) != {"checksum", "data"}:
                problem = "was not written by this version of the engine"
            elif digest_json(doc["data"]) != doc["checksum"]:
                problem = "does not match its checksum (edited or damaged)"
            elif kind is not None and not isinstance(doc["data"], kind):
                problem = f"does not hold a {kind.__name__}"
        except RecursionError:  # parsed, but too deep to hash
            problem = _TOO_DEEP
    if problem is not None:
        if warn:
            warn_once(f"{path} {problem}; {what}")
        return default
    return doc["data"]


def array_checksum(a: np.ndarray) -> str:
    return digest_bytes(np.ascontiguousarray(a).view(np.uint8).reshape(-1).data if a.size else b"")


def file_checksum(path: str) -> str:
    h = hashlib.blake2b(digest_size=16)
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


SEAL_NAME = ".complete"


def _folder_files(folder: str) -> list[str]:
    """Relative paths of the files under ``folder`` (sorted), the seal itself excluded."""
    out = []
    for dirpath, _, filenames in os.walk(folder):
        for fn in filenames:
            rel = os.path.relpath(os.path.join(dirpath, fn), folder)
            if rel != SEAL_NAME:
                out.append(rel)
    return sorted(out)


def seal_folder(folder: str, meta: dict, digest=file_checksum) -> None:
    """Record ``meta`` and the checksum of every file under ``folder`` in ``folder/.complete`` (written last)."""
    files = {rel: digest(os.path.join(folder, rel)) for rel in _folder_files(folder)}
    write_checked_json(os.path.join(folder, SEAL_NAME), {"meta": meta, "files": files})


def check_folder(folder: str, digest=file_checksum) -> str | None:
    """None when ``folder`` holds exactly the files its seal lists, with the same contents; else what differs.

    ``digest(path)``: a content hash (pass a cached one, e.g. the planner's FileHasher.digest)."""
    seal = read_checked_json(os.path.join(folder, SEAL_NAME), "", warn=False)
    if seal is None or not isinstance(seal.get("files"), dict):
        return f"its {SEAL_NAME} record is missing or unusable (written by an older version?)"
    present = _folder_files(folder)
    extra = sorted(set(present) - set(seal["files"]))
    if extra:
        return f"file(s) not written by the generator: {', '.join(extra[:3])}{' ...' if len(extra) > 3 else ''}"
    for rel, sha in seal["files"].items():
        path = os.path.join(folder, rel)
        if not os.path.isfile(path):
            return f"file {rel} is missing"
        if digest(path) != sha:
            return f"file {rel} was changed after it was generated"
    return None


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



def read_checked_arrays(key: str, arrays_meta: dict, verify: bool, open_store,
                        zarr_format: int | None = None) -> dict[str, np.ndarray]:
    """{name: array} of an entry's arrays, each read from ``open_store(name)`` (a zarr store) and checked
    against its manifest record ``arrays_meta[name]`` ({"shape", "sha"}; the checksum only when ``verify``);
    ``zarr_format`` None lets zarr detect it (an object store passes 3 to save the probing requests).

    Raises:
        CorruptEntry: an array is missing, unreadable, or does not match its record.
    """
    import zarr

    arrays = {}
    for name, meta in arrays_meta.items():
        try:
            arr = np.asarray(zarr.open_array(store=open_store(name), mode="r", zarr_format=zarr_format)[...])
        except Exception as exc:  # missing objects or chunk files, bad metadata, decompression errors
            raise CorruptEntry(key, f"array {name}: {type(exc).__name__}: {exc}") from exc
        if list(arr.shape) != meta["shape"] or (verify and array_checksum(arr) != meta["sha"]):
            raise CorruptEntry(key, f"array {name} does not match its checksum")
        arrays[name] = arr
    return arrays

def _decode(tree: Any, arrays: dict[str, np.ndarray]) -> Any:
    if isinstance(tree, dict):
        if "__array__" in tree:
            return arrays[tree["__array__"]]
        return {k: _decode(v, arrays) for k, v in tree["__dict__"].items()}
    if isinstance(tree, list):
        return [_decode(v, arrays) for v in tree]
    return tree


CACHE_MARKER = ".stages-cache"
# what the engine writes at the top of a cache (a folder holding only these may be adopted as a cache)
_CACHE_NAMES = ("manifest", "objects", "runs", "filehash.json", "fingerprints.json", "generated", "tmp", "sweeps",
                CACHE_MARKER)
KEY_PATTERN = re.compile(r"^[0-9a-f]{32}$")
_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*://")


def is_url(location: str) -> bool:
    """True for an object-store URL (``s3://bucket/prefix``), False for a local path."""
    return bool(_URL.match(str(location)))


_UNEXPANDED = re.compile(r"\$(\w+|\{[^}]*\})")


def expand_path(path: str) -> str:
    """``path`` with ``~`` / ``~user`` and ``$VAR`` / ``${VAR}`` expanded as a shell would (a URL as given).

    Raises:
        ValueError: naming what cannot be expanded (an undefined variable, an unknown user), so that no folder
            literally named ``~`` or ``$HOME`` is ever created.
    """
    if is_url(path):
        return path
    out = os.path.expanduser(os.path.expandvars(path))
    left = _UNEXPANDED.search(out)
    if left:
        raise ValueError(f"the path {path!r} names the environment variable {left.group(0)}, which is not set")
    if out.startswith("~"):
        raise ValueError(f"the path {path!r} starts with {out.split(os.sep)[0]!r}, which names no known user's "
                         "home folder")
    return out


def cache_location(location: str) -> str:
    """The cache as the store takes it: a URL as given (without a trailing ``/``), a local path with ``~`` and
    ``$VAR`` expanded (see :func:`expand_path`) and made absolute.

    Raises:
        UserError: the path cannot be expanded.
    """
    if is_url(location):
        return location.rstrip("/")
    try:
        return os.path.abspath(expand_path(location))
    except ValueError as exc:
        raise UserError(f"cache folder: {exc}", fix="set the variable, or write the folder out") from None


_TMP_SUFFIX = r"(\.[0-9a-f]{32}\.tmp)?"   # a half-written file of atomic_write_text
# the files the engine writes in a cache (relative paths, '/'-separated); tmp/ holds none that may be adopted
_ENGINE_FILE = re.compile("^(?:" + "|".join([
    r"manifest/[0-9a-f]{2}/[0-9a-f]{32}\.json" + _TMP_SUFFIX,
    r"objects/[0-9a-f]{2}/[0-9a-f]{32}\.(?:zarr|files)/.+",
    r"runs/[^/]+-[0-9a-f]{10}(?:\.keys)?\.json" + _TMP_SUFFIX,   # the last run, and the ledger of keys (record.py)
    r"sweeps/[^/]+-[0-9a-f]{10}-[0-9a-f]{8}\.json" + _TMP_SUFFIX,
    r"generated/[0-9a-f]{32}/.+",
    r"(?:filehash|fingerprints)\.json" + _TMP_SUFFIX]) + ")$")


def _foreign_content(root: str) -> list[str]:
    """What in the unmarked folder ``root`` the engine did not write (relative paths, at most 5): a top-level
    name that is not exactly one of the engine's, a file at a path the engine never writes, any file under
    ``tmp/`` (its folders are cleaned wholesale, so only an empty one is adopted), any symbolic link.
    Hidden top-level files (.DS_Store, .nfs*) do not count."""
    foreign = sorted(n for n in os.listdir(root) if n not in _CACHE_NAMES and not n.startswith("."))
    for top in sorted(n for n in os.listdir(root) if n in _CACHE_NAMES and n != CACHE_MARKER):
        path = os.path.join(root, top)
        if os.path.islink(path):
            foreign.append(top)
            continue
        walk = os.walk(path) if os.path.isdir(path) else [(root, [], [top])]
        for dirpath, dirnames, filenames in walk:
            for n in dirnames + filenames:
                full = os.path.join(dirpath, n)
                rel = os.path.relpath(full, root).replace(os.sep, "/")
                if os.path.islink(full) or (n in filenames and not _ENGINE_FILE.match(rel)):
                    foreign.append(rel)
            if len(foreign) >= 5:
                return foreign[:5]
    return foreign[:5]


def claim_folder(root: str) -> None:
    """Create the local cache folder ``root`` with its marker, or adopt a folder that holds only what the engine
    writes; leave a read-only folder as it is (see :meth:`Store.claim`).

    Raises:
        UserError: ``root`` is a file, or a folder with other content.
    """
    if os.path.isfile(os.path.join(root, CACHE_MARKER)):
        return
    if os.path.lexists(root) and not os.path.isdir(root):
        raise UserError(f"the cache {root} is not a folder", fix="choose a folder for --cache / 'cache:'")
    if os.path.isdir(root):
        try:
            foreign = _foreign_content(root)
        except OSError as exc:
            raise UserError(f"cannot read the cache folder {root}: {exc.strerror}") from None
        if foreign:
            shown = ", ".join(foreign[:4]) + (" ..." if len(foreign) > 4 else "")
            raise UserError(f"the cache folder {root} is not a stages cache (it holds {shown}, which the engine "
                            f"did not write, and no {CACHE_MARKER} marker): the engine does not write or clean there",
                            fix="choose a new or empty folder for --cache / 'cache:' (e.g. ./cache)")
    try:
        os.makedirs(root, exist_ok=True)
        atomic_write_text(os.path.join(root, CACHE_MARKER),
                          json.dumps({"stages_cache": FORMAT_VERSION, "created": time.time()}))
    except OSError:
        pass  # read-only: reading works; writing commands say so (see writable)


class Store:
    """Content-addressed entries under ``root`` (see module docstring)."""

    def __new__(cls, root: str, warn: bool = True):
        if cls is Store and is_url(root):  # an object-store URL: the entries live there
            from .object_store import ObjectStore
            return super().__new__(ObjectStore)
        return super().__new__(cls)

    def __init__(self, root: str, warn: bool = True):
        """``warn``: print one warning per unreadable entry found (workers pass False: the client warns)."""
        self.root = os.path.abspath(root)
        self.warn = warn

    @property
    def location(self) -> str:
        """Where the entries live, as the user names it (a folder, or a URL for an object store): what a worker
        passes to ``Store(...)``. ``root`` is always a local folder (temporary files, engine tables)."""
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
        manifest = self.manifest(key)
        if manifest is None:
            return False
        problem = self._missing_parts(key, manifest)
        if problem:
            self._warn_unusable(key, problem)
            return False
        return True

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
        doc, problem = _read_json_bytes(path)
        if doc is _ABSENT:
            return None
        if problem is None:
            problem = _manifest_problem(doc, key)
        if problem is not None:
            self._warn_unusable(key, f"its manifest {problem}")
            return None
        _MANIFESTS[path] = ((st.st_size, st.st_mtime_ns), doc)
        return doc

    def left_out(self, key: str) -> list[list[str]]:
        """The items a stored result was computed without (``[[task key, failed task, item, why], ...]``, empty for a
        complete result; see worker.run_task): recorded in the manifest's ``info``."""
        manifest = self.manifest(key)
        return list(manifest["info"].get("left_out", [])) if manifest is not None else []

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

    def _warn_unusable(self, key: str, problem: str) -> None:
        if self.warn:
            info = ""
            hit = _MANIFESTS.get(self.manifest_path(key))
            if hit is not None:
                meta = hit[1].get("info", {})
                info = f" ({meta.get('stage', '')}{'[' + meta['label'] + ']' if meta.get('label') else ''})"
            warn_once(f"cache entry {self.manifest_path(key)}{info}: {problem}; treating it as missing and "
                      "recomputing it")

    def invalidate(self, key: str) -> None:
        """Forget an entry (its manifest), so the next run recomputes it."""
        _READ_CACHE.drop(key)
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
        import zarr

        arrays: dict[str, np.ndarray] = {}
        tree = _encode(value, arrays)
        checksums = {}
        tmp = None
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
        files = {}
        if files_dir and os.path.isdir(files_dir):
            for dirpath, _, filenames in os.walk(files_dir):
                for fn in filenames:
                    full = os.path.join(dirpath, fn)
                    files[os.path.relpath(full, files_dir)] = {"sha": file_checksum(full),
                                                               "size": os.path.getsize(full)}
        manifest = {"format": FORMAT_VERSION, "key": key, "created": time.time(), "tree": tree,
                    "arrays": checksums, "files": files, "info": info or {}}
        manifest = json.loads(json.dumps(manifest, default=_json_default))  # the form a reader sees
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
        import zarr

        signature = (_stat_signature(self.manifest_path(key)), _files_signature(self.object_path(key)))
        cached = _READ_CACHE.get(key)
        if cached is not None and cached[1] == signature:
            return _copy_arrays(cached[0])
        manifest = self.manifest(key)
        if manifest is None:
            raise CorruptEntry(key, "manifest missing or unreadable")
        arrays = read_checked_arrays(key, manifest["arrays"], verify, lambda name: zarr.storage.LocalStore(
            os.path.join(self.object_path(key), name + ".zarr"), read_only=True))
        value = _decode(manifest["tree"], arrays)
        _READ_CACHE.put(key, (value, signature), sum(a.nbytes for a in arrays.values()))
        return _copy_arrays(value)

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
        return sum(_disk_usage(p) for p in (self.object_path(key), self.files_path(key)))

    def stale_writes(self) -> list[tuple[str, int]]:
        """(what, bytes) of data no manifest refers to, for ``gc``: none here (entries are renamed into place);
        an object store lists the writes of runs that lost a race or were killed."""
        return []

    def remove_stale(self, what: str) -> None:
        """Remove one item of :meth:`stale_writes`."""
        raise ValueError(f"{what}: a local cache has no stale writes")


def _disk_usage(path: str) -> int:
    """Bytes of all files under ``path`` (0 if it does not exist)."""
    total = 0
    for dirpath, _, files in os.walk(path):
        for f in files:
            try:
                total += os.path.getsize(os.path.join(dirpath, f))
            except OSError:
                pass
    return total


def same_content(a: dict, b: dict) -> bool:
    """True when two manifests of one key hold the same value: arrays, files, inline tree, and left-out items."""
    return (all(a[f] == b[f] for f in ("tree", "arrays", "files"))
            and a["info"].get("left_out", []) == b["info"].get("left_out", []))


def manifest_checksum(doc: dict) -> str:
    """The checksum a manifest carries: over its fields (and ``location``, which only an object store writes)."""
    fields = _MANIFEST_FIELDS + (("location",) if "location" in doc else ())
    return digest_json({k: doc[k] for k in fields})


def _manifest_problem(doc: Any, key: str) -> str | None:
    """Why a parsed manifest cannot be trusted (None when it can)."""
    try:
        return _manifest_problem_of(doc, key)
    except RecursionError:  # parsed, but too deep to hash
        return _TOO_DEEP


def _manifest_problem_of(doc: Any, key: str) -> str | None:
    if not isinstance(doc, dict) or any(f not in doc for f in _MANIFEST_FIELDS + ("checksum",)):
        return "is incomplete"
    if doc["format"] != FORMAT_VERSION:
        return f"has format {doc['format']!r} (this engine writes {FORMAT_VERSION})"
    if doc["key"] != key:
        return "belongs to another entry"
    if manifest_checksum(doc) != doc["checksum"]:
        return "does not match its checksum (edited or damaged)"
    if not (isinstance(doc["arrays"], dict) and isinstance(doc["files"], dict)
            and all(isinstance(m, dict) and {"sha", "size"} <= set(m) for m in doc["files"].values())):
        return "is malformed"
    return None


# validated manifests of this process: path -> ((size, mtime_ns), manifest)
_MANIFESTS: dict[str, tuple[tuple[int, int], dict]] = {}


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
