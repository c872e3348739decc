"""Publishing: copy the files that file-writing stages stored in the cache to the pipeline's output folder.

The engine replaces only what it wrote itself: ``OUTPUT/.stages-published.json`` lists, per stage, the files
it published (paths relative to OUTPUT) with the checksum of what it wrote, and its own files (``metrics.json``,
sweep figures) likewise. A republish removes the listed files the stage no longer produces and overwrites the
listed ones, as long as they still hold what the engine wrote; a file it did not write, or that was changed
since, is never removed or overwritten (a warning says what to do), and a folder ``OUTPUT/<stage>`` that exists
but was not created by the engine is left alone. Output folders where a stray file could do harm (a filesystem
root, the home folder, the cache) are refused (:func:`check_output_folder`).
"""
from __future__ import annotations

import os
import shutil
import uuid

from . import registry
from .errors import CorruptEntry, UserError, warn_once
from .plan import Plan
from .checksums import file_checksum, read_checked_json, write_checked_json

PUBLISHED_NAME = ".stages-published.json"


def file_stages(plan: Plan) -> list[str]:
    """Names of the stages whose function writes files (receives ``out_dir``)."""
    return [name for name, sp in plan.stages.items()
            if "out_dir" in registry.get(sp.spec.function).engine_args]


def verify_published(plan: Plan) -> tuple[dict[str, dict[str, str]], list[CorruptEntry]]:
    """Check the stored files of every file-writing stage whose tasks are all stored.

    Returns ({task key: {relative path: stored file}} of the entries that verify, [CorruptEntry of those
    that do not]); the caller invalidates the corrupt ones and recomputes them before publishing.
    """
    good: dict[str, dict[str, str]] = {}
    bad: list[CorruptEntry] = []
    for name in file_stages(plan):
        sp = plan.stages[name]
        if not all(plan.store.has(t.key) for t in sp.tasks):
            continue
        for t in sp.tasks:
            try:
                good[t.key] = plan.store.verify_files(t.key)
            except CorruptEntry as exc:
                bad.append(exc)
    return good, bad


def _read_record(out_root: str) -> tuple[dict[str, dict[str, list[str]]], dict[str, list[str]]]:
    """({stage: {relative path: [checksums]}}, {relative path: [checksums]} of the engine's own files such as
    ``metrics.json``) as recorded in ``out_root``. A path's checksums are those of the content the engine wrote
    there (two while a publish replaces it); an empty list (a record of an older engine) trusts any content."""
    rec = read_checked_json(os.path.join(out_root, PUBLISHED_NAME),
                            "its folders are treated as not written by the engine", default={})
    rec = rec if isinstance(rec, dict) else {}

    def paths(v) -> dict[str, list[str]]:
        if isinstance(v, list):  # older record: paths only
            return {p: [] for p in v if isinstance(p, str)}
        if isinstance(v, dict):
            return {p: [c for c in (cs if isinstance(cs, list) else [cs]) if isinstance(c, str)]
                    for p, cs in v.items() if isinstance(p, str)}
        return {}
    stages = rec.get("stages", {})
    stages = {k: paths(v) for k, v in stages.items()} if isinstance(stages, dict) else {}
    if rec and "files" not in rec:  # a record of an older engine, which always wrote these there
        return stages, {name: [] for name in _LEGACY_FILES}
    return stages, paths(rec.get("files", {}))


_LEGACY_FILES = ("metrics.json", "report.html")


def published_record(out_root: str) -> dict[str, list[str]]:
    """{stage: [paths relative to ``out_root``]} the engine published there (empty when there is none)."""
    return {k: sorted(v) for k, v in _read_record(out_root)[0].items()}


def _save_record(out_root: str, owned: dict[str, dict[str, list[str]]], files: dict[str, list[str]]) -> None:
    write_checked_json(os.path.join(out_root, PUBLISHED_NAME),
                       {"stages": {k: dict(sorted(v.items())) for k, v in owned.items()},
                        "files": dict(sorted(files.items()))})


def _is_engines(path: str, checksums: list[str]) -> bool:
    """True when the file at ``path`` still holds what the engine wrote there (any content for a record of an
    older engine, which kept no checksums); a file the user changed or replaced is theirs."""
    if os.path.islink(path):
        return False  # the engine writes no links
    if not checksums:
        return True
    try:
        return file_checksum(path) in checksums
    except OSError:
        return False


_NOT_YOURS = ("{path} exists and was not written by the engine (or was changed since): left as it is ({where}; "
              "move or remove the file to publish it, or publish elsewhere with --out FOLDER)")


def check_output_folder(out_root: str, cache_root: str | None = None) -> None:
    """Refuse an output folder the engine must never publish into: the filesystem root or any mount point,
    the home folder or a folder above it, the cache folder or a folder inside it.

    Raises:
        UserError: naming the folder and what to do.
    """
    out = os.path.realpath(out_root)
    home = os.path.realpath(os.path.expanduser("~"))
    why = None
    if out == os.path.dirname(out) or os.path.ismount(out):
        why = "is the root of a filesystem"
    elif os.path.commonpath([out, home]) == out:
        why = "is your home folder" if out == home else f"holds your home folder {home}"
    elif cache_root and os.path.commonpath([out, os.path.realpath(cache_root)]) == os.path.realpath(cache_root):
        why = f"is {'the' if out == os.path.realpath(cache_root) else 'inside the'} cache folder {cache_root}"
    if why:
        raise UserError(f"the output folder {out_root} {why}: the engine does not publish there",
                        fix="give a folder of its own with --out FOLDER or 'output:' (e.g. results/NAME)")


def write_output_file(out_root: str, rel: str, write,
                      where: str | None = "the values are in the cache: `python -m stages results`") -> str | None:
    """Write one file of the engine's own (``metrics.json``, a sweep figure) at ``out_root/rel`` by calling
    ``write(path)``, unless a file the engine did not write (or that was changed since) is there: then warn
    (``where``: where the content is instead; None: no warning, the caller reports it), leave it and return
    None. Returns the path written; the file's checksum is recorded in the publish record.
    """
    owned, files = _read_record(out_root)
    dst = os.path.join(out_root, rel)
    if os.path.lexists(dst) and (rel not in files or not _is_engines(dst, files[rel])):
        if where is not None:
            warn_once(_NOT_YOURS.format(path=dst, where=where))
        return None
    os.makedirs(os.path.dirname(dst), exist_ok=True)
    tmp = f"{dst}.{uuid.uuid4().hex}.tmp"
    try:
        write(tmp)
        sha = file_checksum(tmp)
        files[rel] = sorted(set(files.get(rel, [])) | {sha})  # recorded first: a kill leaves it known
        _save_record(out_root, owned, files)
        os.replace(tmp, dst)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    files[rel] = [sha]
    _save_record(out_root, owned, files)
    return dst


def publish(plan: Plan, log, verified: dict[str, dict[str, str]] | None = None) -> list[str]:
    """Copy the files of every file-writing stage from the cache to ``<output>/<stage>/`` (per-item stages:
    ``<output>/<stage>/<item>/``); a stage is published only when all its tasks are stored.

    verified: {task key: {relative path: stored file}} from :func:`verify_published` (checked again if absent).
    Returns the absolute paths written. Raises CorruptEntry when a stored file fails its checksum, and
    UserError when the output folder cannot be written.
    """
    out_root = plan.pipeline.output_dir
    check_output_folder(out_root, plan.store.root)
    try:
        return _publish(plan, out_root, verified or {})
    except OSError as exc:
        raise UserError(f"cannot write the output folder {out_root}: {exc.strerror or exc}"
                        + (f" ({exc.filename})" if exc.filename else ""),
                        fix="make it writable or publish elsewhere with --out FOLDER; every result is stored in "
                            "the cache, so the next run only copies the files") from None


def _publish(plan: Plan, out_root: str, verified: dict[str, dict[str, str]]) -> list[str]:
    owned, files = _read_record(out_root)
    written: list[str] = []
    for name in file_stages(plan):
        sp = plan.stages[name]
        if not all(plan.store.has(t.key) for t in sp.tasks):
            continue
        target = os.path.join(out_root, name)
        if os.path.lexists(target) and not os.path.isdir(target):
            warn_once(f"{target} exists and is not a folder: stage '{name}' is not published")
            continue
        new: dict[str, tuple[str, str]] = {}  # relative path -> (stored file, its checksum)
        for t in sp.tasks:
            stored = verified[t.key] if t.key in verified else plan.store.verify_files(t.key)
            base = os.path.join(name, t.label) if sp.spec.fanout == "item" else name
            for rel, src in stored.items():
                rel = os.path.normpath(os.path.join(base, rel))
                if rel.split(os.sep)[0] != name:
                    raise CorruptEntry(t.key, f"stored file path {rel!r} leaves the stage's folder")
                new[rel] = (src, file_checksum(src))
        if name not in owned and os.path.isdir(target) and os.listdir(target):
            present = _files_under(out_root, target)
            if not present or not all(rel in new and _is_engines(os.path.join(out_root, rel), [new[rel][1]])
                                      for rel in present):
                warn_once(f"{target} exists and was not written by the engine: stage '{name}' is not published "
                          "there (move that folder away, or publish elsewhere with --out FOLDER)")
                continue
            owned[name] = {rel: [new[rel][1]] for rel in present}  # exactly this stage's files: the engine's
        before = owned.get(name, {})
        mine = {rel: cs for rel, cs in before.items()
                if os.path.lexists(os.path.join(out_root, rel)) and _is_engines(os.path.join(out_root, rel), cs)}
        # recorded first (old and new checksums): an interrupted publish still knows its files
        owned[name] = {rel: sorted(set(mine.get(rel, [])) | ({new[rel][1]} if rel in new else set()))
                       for rel in set(mine) | set(new)}
        os.makedirs(out_root, exist_ok=True)
        _save_record(out_root, owned, files)
        for rel in sorted(set(before) - set(new)):
            if rel in mine:
                _remove_published(out_root, rel, target)
        kept = {}
        for rel, (src, sha) in sorted(new.items()):
            dst = os.path.join(out_root, rel)
            if os.path.lexists(dst) and rel not in mine:
                if _is_engines(dst, [sha]):  # already holds exactly this content (e.g. the record was lost)
                    kept[rel] = [sha]
                    continue
                warn_once(_NOT_YOURS.format(path=dst, where="the stage's version is in the cache"))
                continue
            _copy_atomic(src, dst)
            kept[rel] = [sha]
            written.append(dst)
        owned[name] = kept
        _save_record(out_root, owned, files)
    return written


def _files_under(out_root: str, folder: str) -> list[str]:
    """Paths relative to ``out_root`` of the files (and links) under ``folder``."""
    return [os.path.relpath(os.path.join(d, f), out_root) for d, dirs, files in os.walk(folder) for f in files + [
        x for x in dirs if os.path.islink(os.path.join(d, x))]]


def _copy_atomic(src: str, dst: str) -> None:
    os.makedirs(os.path.dirname(dst), exist_ok=True)
    tmp = f"{dst}.{uuid.uuid4().hex}.tmp"
    try:
        shutil.copyfile(src, tmp)
        os.replace(tmp, dst)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def _remove_published(out_root: str, rel: str, stage_dir: str) -> None:
    """Remove one file the engine published earlier, and the folders it leaves empty (up to ``stage_dir``)."""
    path = os.path.join(out_root, rel)
    if os.path.commonpath([os.path.abspath(path), os.path.abspath(stage_dir)]) != os.path.abspath(stage_dir):
        return  # a record entry outside the stage's folder: never followed
    try:
        os.remove(path)
    except FileNotFoundError:
        pass
    parent = os.path.dirname(path)
    while os.path.abspath(parent) != os.path.abspath(stage_dir) and parent.startswith(stage_dir):
        try:
            os.rmdir(parent)
        except OSError:
            break
        parent = os.path.dirname(parent)
