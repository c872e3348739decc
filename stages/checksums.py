"""Content digests, and the engine's JSON files: written atomically with a checksum, read back checked."""
from __future__ import annotations

import hashlib
import json
import os
import uuid
from typing import Any

import numpy as np

from .errors import warn_once


def digest_bytes(data: bytes | memoryview) -> str:
    """A short hex content hash."""
    return hashlib.blake2b(data, digest_size=16).hexdigest()


def digest_json(obj: Any) -> str:
    """Hash of the canonical JSON of ``obj`` (sorted keys, no whitespace)."""
    return digest_bytes(canonical_json(obj).encode())


def canonical_json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=json_default)


def json_default(o: Any):
    """``json.dumps(default=...)`` for numpy scalars and arrays."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON-serializable: {type(o).__name__}")


def array_checksum(a: np.ndarray) -> str:
    return digest_bytes(np.ascontiguousarray(a).view(np.uint8).reshape(-1).data if a.size else b"")


def file_checksum(path: str) -> str:
    h = hashlib.blake2b(digest_size=16)
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


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


ABSENT = object()   # what read_json_bytes returns for a file that does not exist
TOO_DEEP = "is nested too deeply to be read (damaged or not written by the engine)"


def read_json_bytes(path: str) -> tuple[Any, str | None]:
    """(parsed JSON, None), or (None, why it is unusable); (ABSENT, None) when the file does not exist."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except FileNotFoundError:
        return ABSENT, None
    except OSError as exc:
        return None, f"cannot be read ({exc.strerror or exc})"
    return parse_json(data)


def parse_json(data: bytes) -> tuple[Any, str | None]:
    """(parsed JSON of the UTF-8 ``data``, None), or (None, why it is unusable)."""
    try:
        return json.loads(data.decode("utf-8")), None
    except UnicodeDecodeError:
        return None, "is not UTF-8 text (overwritten or damaged)"
    except ValueError:
        return None, "is not valid JSON (truncated or edited)"
    except RecursionError:  # e.g. '[' * 200000: damaged, like a truncated file (never a traceback)
        return None, TOO_DEEP


def write_checked_json(path: str, obj: Any) -> None:
    """Write ``obj`` atomically as ``{"checksum": ..., "data": obj}`` (see :func:`read_checked_json`)."""
    data = json.loads(json.dumps(obj, default=json_default))
    atomic_write_text(path, json.dumps({"checksum": digest_json(data), "data": data}))


def read_checked_json(path: str, what: str, default: Any = None, kind: type | None = dict,
                      warn: bool = True) -> Any:
    """The ``data`` written by :func:`write_checked_json`, or ``default`` when the file is missing or unusable.

    Unusable (truncated, not UTF-8, not JSON, checksum mismatch, not a ``kind``) means: warn once naming the
    file and what happens (``what``, e.g. "rebuilding it"), and return ``default``; never raise.
    """
    doc, problem = read_json_bytes(path)
    if doc is ABSENT:
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
            problem = TOO_DEEP
    if problem is not None:
        if warn:
            warn_once(f"{path} {problem}; {what}")
        return default
    return doc["data"]
