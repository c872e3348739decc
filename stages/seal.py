"""Sealed folders: the checksum of every file in a folder recorded in its ``.complete`` file, and checked."""
from __future__ import annotations

import os

from .checksums import file_checksum, read_checked_json, write_checked_json

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
