"""The cache's location and ownership: local paths and URLs, the engine's marker, claiming a folder as a cache."""
from __future__ import annotations

import json
import os
import re
import time

from .checksums import atomic_write_text
from .errors import UserError
from .manifest import FORMAT_VERSION

CACHE_MARKER = ".stages-cache"
# what the engine writes at the top of a cache (a folder holding only these may be adopted as a cache)
CACHE_NAMES = ("manifest", "objects", "runs", "filehash.json", "fingerprints.json", "generated", "tmp", "sweeps",
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
    foreign = sorted(n for n in os.listdir(root) if n not in CACHE_NAMES and not n.startswith("."))
    for top in sorted(n for n in os.listdir(root) if n in CACHE_NAMES and n != CACHE_MARKER):
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
