"""The result store on object storage (``--cache s3://bucket/prefix``): zarr's fsspec store, same guarantees.

Layout under the URL::

    .stages-cache                       the marker (written when the engine creates the cache; gc needs it)
    manifest/ab/<key>.json              the entry's manifest: the commit point, written last
    objects/ab/<key>/<writer>/aN.zarr   the arrays one writer stored (zarr v3 through zarr.storage.FsspecStore)
    objects/ab/<key>/<writer>/files/    the files a stage published

An object store has no rename, so an entry is never moved into place. Instead every writer (one task of one
run) writes its data under its own random ``<writer>`` prefix, never touched by anybody else, and only then
the manifest, which names that prefix (``location``) and carries the checksum of every array and file and of
itself. The manifest is written with ``If-None-Match: *`` (a conditional, create-only PUT): of two runs
computing the same entry, the first manifest wins, the other run sees that the entry is complete and deletes
its own data. A PUT replaces a whole object at once, so a reader sees the old or the new manifest, never a
mix, and the manifest it sees always names one writer's complete data: an entry without a valid manifest is
missing (recomputed, with a warning when a manifest was there but unusable), exactly as on a local disk. A
server without conditional writes falls back to a plain PUT (last writer wins; still one writer's complete
data); the loser's data is then left for ``gc`` (:meth:`ObjectStore.stale_writes`).

What has to be a local file stays in a local folder (``root``): temporary files, generated datasets, the
engine's tables (``filehash.json``, ``fingerprints.json``, ``runs/``, ``sweeps/``) and the copies of
published files. It is ``$STAGES_LOCAL_CACHE/<scheme>/<bucket>/<prefix>`` (default base
``$XDG_CACHE_HOME/stages`` or ``~/.cache/stages``). Connection options come from the environment as for any
fsspec/boto client: ``AWS_ENDPOINT_URL``, ``AWS_ACCESS_KEY_ID``, ``AWS_SECRET_ACCESS_KEY``,
``AWS_DEFAULT_REGION``, ``AWS_PROFILE`` ..., or the fsspec configuration (``~/.config/fsspec/s3.json``,
``FSSPEC_S3_<OPTION>`` variables).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import time
import uuid
from typing import Any

import numpy as np

from .errors import CorruptEntry, UserError, warn_once
from .cache_root import CACHE_MARKER, CACHE_NAMES, KEY_PATTERN, claim_folder
from .checksums import file_checksum, json_default, parse_json
from .codec import copy_arrays, decode, encode, read_checked_arrays, write_arrays
from .manifest import FORMAT_VERSION, manifest_checksum, manifest_problem, same_content
from .read_cache import READ_CACHE
from .store import Store

# a write under objects/ that no manifest names and that is younger than this may belong to a task still
# running (its manifest comes last): gc leaves it alone
STALE_WRITE_S = 3600.0
# fsspec options the engine sets: no listing cache (other runs add entries while this one runs); one request
# per read (s3fs asks for the size first, to split big reads, when max_concurrency > 1; our objects are small)
_FS_OPTIONS = {"use_listings_cache": False, "max_concurrency": 1}
_FIX_SETUP = ("install the s3 extra on this machine and on every worker (pip install -e '.[s3]'), and set "
              "AWS_ENDPOINT_URL (for a non-AWS server), AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY, "
              "or use a local folder for --cache")


def local_folder(location: str) -> str:
    """The local folder of the object-store cache ``location`` (``scheme://bucket/prefix``): see the module doc."""
    base = os.environ.get("STAGES_LOCAL_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "stages")
    scheme, rest = location.split("://", 1)
    parts = [re.sub(r"[^A-Za-z0-9._\-]", "_", p) for p in rest.split("/") if p not in ("", ".", "..")]
    return os.path.join(os.path.abspath(base), re.sub(r"[^A-Za-z0-9]", "_", scheme), *parts)


class ObjectStore(Store):
    """Content-addressed entries at an object-store URL (see the module docstring); ``root`` is local."""

    def __init__(self, location: str, warn: bool = True):
        self._location = location.rstrip("/")
        self.protocol, rest = self._location.split("://", 1)
        self.base = rest.strip("/")   # bucket/prefix, as fsspec paths are written
        if not self.base:
            raise UserError(f"the cache URL {location!r} names no bucket", fix="write it as s3://BUCKET/PREFIX")
        self.root = local_folder(self._location)
        self.warn = warn
        self._fs = None
        self._read_only = False

    @property
    def location(self) -> str:
        return self._location

    @property
    def fs(self):
        """The fsspec file system (created on first use; options from the environment), its calls raising
        UserError when the store cannot be reached or refuses the credentials (see :meth:`_unreachable`)."""
        if self._fs is None:
            try:
                import fsspec
                self._fs = _Translated(fsspec.filesystem(self.protocol, **_FS_OPTIONS), self)
            except (ImportError, ValueError) as exc:
                raise UserError(f"the cache {self._location} cannot be opened: {exc}", fix=_FIX_SETUP) from None
        return self._fs

    def endpoint(self) -> str:
        """The endpoint the store talks to, for messages."""
        fs = self._fs.fs if self._fs is not None else None
        url = (getattr(fs, "endpoint_url", None) or (getattr(fs, "client_kwargs", None) or {}).get("endpoint_url")
               or os.environ.get("AWS_ENDPOINT_URL_S3") or os.environ.get("AWS_ENDPOINT_URL"))
        return url or f"the default {self.protocol} endpoint"

    def _zarr_store(self, path: str, read_only: bool):
        import zarr
        return zarr.storage.FsspecStore.from_url(f"{self.protocol}://{path}", storage_options=dict(_FS_OPTIONS),
                                                 read_only=read_only)

    def _unreachable(self, exc: BaseException, doing: str) -> UserError:
        """The error to report when the store cannot be used (``exc``: what the client raised), naming the cache,
        the endpoint and what to do; every entry stored so far stays stored."""
        cause = _access_problem(exc) or exc
        name = type(cause).__name__
        detail = str(cause).splitlines()[0] if str(cause) else "no answer"
        kept = "; every result stored so far is kept, run again once it answers"
        if "Credential" in name or "credential" in detail.lower():
            return UserError(f"cannot {doing} the cache {self._location} (endpoint {self.endpoint()}): no usable "
                             f"credentials ({name}: {detail})",
                             fix="set AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY (or AWS_PROFILE) on this machine "
                                 "and on every worker, or use a local folder for --cache")
        if _access_problem(exc) is not None:
            return UserError(f"cannot {doing} the cache {self._location}: the endpoint {self.endpoint()} does not "
                             f"answer ({name}: {detail})",
                             fix="check that the server is running and reachable from here and from every worker, "
                                 "and that AWS_ENDPOINT_URL names it" + kept)
        return UserError(f"cannot {doing} the cache {self._location} (endpoint {self.endpoint()}): {name}: {detail}",
                         fix=_FIX_SETUP)

    # paths (fsspec paths: bucket/prefix/...; manifest_path is the URL, for messages) --------------
    def _manifest_key(self, key: str) -> str:
        return f"{self.base}/manifest/{key[:2]}/{key}.json"

    def manifest_path(self, key: str) -> str:
        return f"{self.protocol}://{self._manifest_key(key)}"

    def object_path(self, key: str) -> str:
        """The entry's data, of every writer (``objects/ab/<key>``)."""
        return f"{self.base}/objects/{key[:2]}/{key}"

    def _data(self, key: str, writer: str) -> str:
        return f"{self.object_path(key)}/{writer}"

    def files_path(self, key: str) -> str:
        """The local copies of the entry's published files (checked against the manifest before use)."""
        return os.path.join(self.root, "objects", key[:2], key + ".files")

    # ownership ---------------------------------------------------------------------------------
    def exists(self) -> bool:
        try:
            return self.fs.exists(f"{self.base}/{CACHE_MARKER}") or bool(self._top_names())
        except FileNotFoundError:
            return False

    def _top_names(self) -> list[str]:
        try:
            return sorted(p.rstrip("/").rsplit("/", 1)[-1] for p in self.fs.ls(self.base, detail=False))
        except FileNotFoundError:
            return []

    def is_marked(self) -> bool:
        try:
            return self.fs.isfile(f"{self.base}/{CACHE_MARKER}")
        except FileNotFoundError:
            return False
        except OSError as exc:
            raise self._unreachable(exc, "read") from None

    def claim(self) -> None:
        """Claim the local folder, then the URL: write the marker, or refuse a prefix with other content (e.g. a
        bucket of yours): the engine neither writes nor cleans there.

        Raises:
            UserError: foreign content, a bucket that does not exist, or a store that cannot be reached.
        """
        claim_folder(self.root)
        try:
            if self.is_marked():
                return
            foreign = [n for n in self._top_names() if n not in CACHE_NAMES and not n.startswith(".")]
        except UserError:
            raise
        except OSError as exc:
            raise self._unreachable(exc, "read") from None
        if foreign:
            shown = ", ".join(foreign[:4]) + (" ..." if len(foreign) > 4 else "")
            raise UserError(f"the cache {self._location} is not a stages cache (it holds {shown} and no "
                            f"{CACHE_MARKER} marker): the engine does not write or clean there",
                            fix="choose a new or empty prefix for --cache / 'cache:' (e.g. s3://BUCKET/stages-cache)")
        marker = json.dumps({"stages_cache": FORMAT_VERSION, "created": time.time()}).encode()
        try:
            self._create(f"{self.base}/{CACHE_MARKER}", marker)
        except FileExistsError:
            pass  # another run claimed it at the same moment
        except PermissionError:
            self._read_only = True
        except FileNotFoundError:
            raise UserError(f"the bucket of the cache {self._location} does not exist",
                            fix=f"create it (e.g. `aws s3 mb s3://{self.base.split('/')[0]}`) or use another URL") from None
        except OSError as exc:
            raise self._unreachable(exc, "write") from None

    def writable(self) -> bool:
        return not self._read_only and os.access(self.root, os.W_OK | os.X_OK)

    def _create(self, path: str, data: bytes) -> None:
        """PUT ``data`` at ``path`` only if nothing is there (FileExistsError otherwise); a server without
        conditional writes gets a plain PUT."""
        try:
            self.fs.pipe_file(path, data, mode="create")
        except NotImplementedError:
            self.fs.pipe_file(path, data)

    # queries -----------------------------------------------------------------------------------
    def manifest(self, key: str) -> dict | None:
        """The entry's manifest, or None when it is missing or unusable (warned once).

        Raises:
            UserError: the store cannot be reached (credentials, endpoint): not a reason to recompute everything.
        """
        try:
            data = self.fs.cat_file(self._manifest_key(key))
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise self._unreachable(exc, "read") from None
        doc, problem = parse_json(data)
        if problem is None:
            problem = manifest_problem(doc, key)
        if problem is None and not (isinstance(doc.get("location"), str) and KEY_PATTERN.match(doc["location"])):
            problem = "names no data location (not written for an object store)"
        if problem is not None:
            self._warn_unusable(key, f"its manifest {problem}")
            return None
        return doc

    def manifest_exists(self, key: str) -> bool:
        try:
            return self.fs.isfile(self._manifest_key(key))
        except OSError:
            return False

    def _missing_parts(self, key: str, manifest: dict) -> str | None:
        """What is wrong with the first array or file of the entry that is absent or has another size (one
        listing of the writer's prefix), else None."""
        if not manifest["arrays"] and not manifest["files"]:
            return None
        data = self._data(key, manifest["location"])
        try:
            sizes = {p: info.get("size") for p, info in self.fs.find(data, detail=True).items()}
        except FileNotFoundError:
            sizes = {}
        for name in manifest["arrays"]:
            if f"{data}/{name}.zarr/zarr.json" not in sizes:
                return f"array {name} is missing"
        for rel, meta in manifest["files"].items():
            size = sizes.get(f"{data}/files/{rel}")
            if size is None:
                return f"published file {rel} is missing"
            if size != meta["size"]:
                return f"published file {rel} was changed"
        return None

    def _warn_unusable(self, key: str, problem: str, manifest: dict | None = None) -> None:
        if self.warn:
            meta = (manifest or {}).get("info", {})
            info = f" ({meta.get('stage', '')}{'[' + meta['label'] + ']' if meta.get('label') else ''})" if meta else ""
            warn_once(f"cache entry {self.manifest_path(key)}{info}: {problem}; treating it as missing and "
                      "recomputing it")

    def invalidate(self, key: str) -> None:
        """Forget an entry (delete its manifest); its data is left to ``gc`` (:meth:`stale_writes`)."""
        READ_CACHE.drop(key)
        try:
            self.fs.rm_file(self._manifest_key(key))
        except FileNotFoundError:
            pass

    # write -------------------------------------------------------------------------------------
    def put(self, key: str, value: Any, info: dict | None = None, files_dir: str | None = None) -> dict:
        """Store ``value`` (and the files in ``files_dir``, a local folder removed afterwards) under ``key``.

        Data first, under this writer's own prefix; the manifest last, create-only. Returns the manifest of
        the entry as stored: this one, or the one of a run that stored the same key first.
        """
        arrays: dict[str, np.ndarray] = {}
        tree = encode(value, arrays)
        writer = uuid.uuid4().hex
        data = self._data(key, writer)
        committing = False
        try:
            checksums = write_arrays({name: self._zarr_store(f"{data}/{name}.zarr", read_only=False)
                                      for name in arrays}, arrays)
            files = {}
            if files_dir and os.path.isdir(files_dir):
                for dirpath, _, filenames in os.walk(files_dir):
                    for fn in filenames:
                        full = os.path.join(dirpath, fn)
                        rel = os.path.relpath(full, files_dir)
                        files[rel] = {"sha": file_checksum(full), "size": os.path.getsize(full)}
                        self.fs.put_file(full, f"{data}/files/{rel.replace(os.sep, '/')}")
            manifest = {"format": FORMAT_VERSION, "key": key, "created": time.time(), "tree": tree,
                        "arrays": checksums, "files": files, "info": info or {}, "location": writer}
            manifest = json.loads(json.dumps(manifest, default=json_default))  # the form a reader sees
            manifest["checksum"] = manifest_checksum(manifest)
            committing = True
            return self._commit(key, manifest)
        except BaseException as exc:
            if not committing:  # once the manifest's PUT is sent it may be stored (its answer lost): the data
                self._remove_quietly(data)  # stays, for gc to remove when no manifest names it
            if not isinstance(exc, UserError) and _access_problem(exc) is not None:
                raise self._unreachable(exc, "write") from None
            raise
        finally:
            if files_dir:
                shutil.rmtree(files_dir, ignore_errors=True)

    def _commit(self, key: str, manifest: dict) -> dict:
        """Write the manifest unless a complete entry is already there (then keep that one, drop this data)."""
        body = json.dumps(manifest).encode()
        try:
            self._create(self._manifest_key(key), body)
            return manifest
        except FileExistsError:
            pass
        kept = self._quiet_manifest(key)
        if kept is not None and kept["location"] == manifest["location"]:
            return manifest  # this writer's own: its create was stored, and a retry of it (answer lost) refused
        if kept is not None and same_content(kept, manifest) and self._missing_parts(key, kept) is None:
            self._remove_quietly(self._data(key, manifest["location"]))  # same key, same content: stored once
            return kept
        # the one there is unusable, or holds other content (a result computed without some failed items, now
        # computed with them): replace it with one PUT; its data is left to gc
        self.fs.pipe_file(self._manifest_key(key), body)
        return manifest

    def _remove_quietly(self, path: str) -> None:
        try:
            self.fs.rm(path, recursive=True)
        except (FileNotFoundError, OSError, UserError):
            pass

    # read --------------------------------------------------------------------------------------
    def get(self, key: str, verify: bool = True) -> Any:
        """Load an entry's value; with ``verify`` every array is checked against its checksum.

        Raises:
            CorruptEntry: missing data or checksum mismatch (the caller recomputes the entry).
        """
        manifest = self.manifest(key)
        if manifest is None:
            raise CorruptEntry(key, "manifest missing or unreadable")
        signature = ("object-store", manifest["checksum"])  # names the writer: its data is never rewritten
        cached = READ_CACHE.get(key)
        if cached is not None and cached[1] == signature:
            return copy_arrays(cached[0])
        data = self._data(key, manifest["location"])
        try:
            arrays = read_checked_arrays(key, manifest["arrays"], verify,
                                         lambda name: self._zarr_store(f"{data}/{name}.zarr", read_only=True),
                                         zarr_format=3)
        except CorruptEntry as exc:
            if _access_problem(exc) is not None:  # the server went away: not a reason to recompute the entry
                raise self._unreachable(exc, "read") from None
            raise
        value = decode(manifest["tree"], arrays)
        READ_CACHE.put(key, (value, signature), sum(a.nbytes for a in arrays.values()))
        return copy_arrays(value)

    def verify_files(self, key: str) -> dict[str, str]:
        """{relative path: local copy} of the entry's files, each checked against its checksum; a local copy
        that does not match (or is absent) is downloaded again first.

        Raises:
            CorruptEntry: the manifest is unusable, or a stored file is missing or changed.
        """
        manifest = self.manifest(key)
        if manifest is None:
            raise CorruptEntry(key, "manifest missing or unreadable")
        local = self.files_path(key)
        out = {}
        for rel, meta in manifest["files"].items():
            full = os.path.normpath(os.path.join(local, rel))
            if os.path.commonpath([full, local]) != local:
                raise CorruptEntry(key, f"stored file path {rel!r} leaves the entry's folder")
            if not (os.path.isfile(full) and file_checksum(full) == meta["sha"]):
                self._download(f"{self._data(key, manifest['location'])}/files/{rel.replace(os.sep, '/')}", full)
                if not (os.path.isfile(full) and file_checksum(full) == meta["sha"]):
                    raise CorruptEntry(key, f"published file {rel} is missing or changed")
            out[rel] = full
        return out

    def _download(self, path: str, dst: str) -> None:
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        tmp = f"{dst}.{uuid.uuid4().hex}.tmp"
        try:
            self.fs.get_file(path, tmp)
            os.replace(tmp, dst)
        except FileNotFoundError:
            pass  # reported by the caller as missing
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)

    # maintenance -------------------------------------------------------------------------------
    def all_keys(self) -> list[str]:
        try:
            paths = self.fs.find(f"{self.base}/manifest")
        except FileNotFoundError:
            return []
        names = (p.rsplit("/", 1)[-1] for p in paths)
        return [n[:-5] for n in names if n.endswith(".json") and KEY_PATTERN.match(n[:-5])]

    def remove(self, key: str) -> None:
        self.invalidate(key)
        self._remove_quietly(self.object_path(key))
        shutil.rmtree(self.files_path(key), ignore_errors=True)

    def entry_bytes(self, key: str) -> int:
        try:
            return sum(int(i.get("size") or 0) for i in self.fs.find(self.object_path(key), detail=True).values())
        except FileNotFoundError:
            return 0

    def stale_writes(self) -> list[tuple[str, int]]:
        """(writer prefix, bytes) of the data under ``objects/`` that no usable manifest names (a run that lost
        a race on a server without conditional writes, a killed task, an invalidated entry), last written more
        than STALE_WRITE_S ago (a younger one may be a task that has not written its manifest yet). Only
        names the engine gives its objects are listed."""
        try:
            listing = self.fs.find(f"{self.base}/objects", detail=True)
        except FileNotFoundError:
            return []
        writes: dict[tuple[str, str], list[dict]] = {}
        shape = re.compile(rf"^{re.escape(self.base)}/objects/([0-9a-f]{{2}})/([0-9a-f]{{32}})/([0-9a-f]{{32}})/")
        for path, info in listing.items():
            m = shape.match(path)
            if m and m.group(2).startswith(m.group(1)):
                writes.setdefault((m.group(2), m.group(3)), []).append(info)
        now, named, out = time.time(), {}, []
        for (key, writer), infos in sorted(writes.items()):
            if key not in named:
                doc = self._quiet_manifest(key)
                named[key] = doc["location"] if doc is not None else None
            if named[key] == writer:
                continue
            newest = max((_mtime(i) for i in infos), default=now)
            if now - newest > STALE_WRITE_S:
                out.append((self._data(key, writer), sum(int(i.get("size") or 0) for i in infos)))
        return out

    def remove_stale(self, what: str) -> None:
        if not re.match(rf"^{re.escape(self.base)}/objects/[0-9a-f]{{2}}/[0-9a-f]{{32}}/[0-9a-f]{{32}}$", what):
            raise ValueError(f"refusing to remove {what}: not a writer prefix of the cache {self._location}")
        self._remove_quietly(what)


def _access_problem(exc: BaseException | None) -> BaseException | None:
    """The exception in ``exc``'s chain that says the store cannot be reached or refuses the client (connection
    refused or reset, timeout, no credentials: botocore's errors, aiohttp's connection errors, ConnectionError),
    or None (a missing object, a bad request: handled where they occur)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        names = {c.__name__ for c in type(exc).__mro__}
        module = type(exc).__module__ or ""
        if (isinstance(exc, (ConnectionError, TimeoutError)) or "BotoCoreError" in names
                or "ClientConnectionError" in names or "ServerTimeoutError" in names
                or (module.startswith(("botocore", "aiobotocore", "aiohttp")) and "Connect" in type(exc).__name__)):
            return exc
        exc = exc.__cause__ or exc.__context__
    return None


class _Translated:
    """An fsspec file system whose calls raise ``store._unreachable(...)`` (a UserError naming the endpoint and
    the fix) instead of the client's connection and credential errors; everything else passes through."""

    def __init__(self, fs, store: "ObjectStore"):
        self.fs, self._store = fs, store

    def __getattr__(self, name: str):
        attr = getattr(self.fs, name)
        if not callable(attr):
            return attr

        def call(*args, **kwargs):
            try:
                return attr(*args, **kwargs)
            except Exception as exc:
                if _access_problem(exc) is None:
                    raise
                raise self._store._unreachable(exc, "write" if name in _WRITES else "read") from None
        return call


_WRITES = {"pipe_file", "put_file", "rm", "rm_file", "mkdir", "makedirs", "touch"}


def _mtime(info: dict) -> float:
    """Seconds since the epoch at which the object described by ``info`` (an fsspec listing entry) was written."""
    t = info.get("LastModified") or info.get("mtime") or info.get("last_modified")
    if hasattr(t, "timestamp"):
        return t.timestamp()
    return float(t) if t is not None else time.time()
