"""An entry's manifest: its fields and format version, its checksum, and whether a parsed one can be trusted."""
from __future__ import annotations

from typing import Any

from .checksums import TOO_DEEP, digest_json

FORMAT_VERSION = 2
MANIFEST_FIELDS = ("format", "key", "created", "tree", "arrays", "files", "info")


def same_content(a: dict, b: dict) -> bool:
    """True when two manifests of one key hold the same value: arrays, files, inline tree, and left-out items."""
    return (all(a[f] == b[f] for f in ("tree", "arrays", "files"))
            and a["info"].get("left_out", []) == b["info"].get("left_out", []))


def manifest_checksum(doc: dict) -> str:
    """The checksum a manifest carries: over its fields (and ``location``, which only an object store writes)."""
    fields = MANIFEST_FIELDS + (("location",) if "location" in doc else ())
    return digest_json({k: doc[k] for k in fields})


def manifest_problem(doc: Any, key: str) -> str | None:
    """Why a parsed manifest cannot be trusted (None when it can)."""
    try:
        return _manifest_problem_of(doc, key)
    except RecursionError:  # parsed, but too deep to hash
        return TOO_DEEP


def _manifest_problem_of(doc: Any, key: str) -> str | None:
    if not isinstance(doc, dict) or any(f not in doc for f in MANIFEST_FIELDS + ("checksum",)):
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
