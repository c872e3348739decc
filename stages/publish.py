"""Publishing: copy the files that file-writing stages stored in the cache to the pipeline's output folder.

The engine replaces only what it wrote itself: ``OUTPUT/.stages-published.json`` lists, per stage, the files
it published (paths relative to OUTPUT). A republish removes the listed files the stage no longer produces
and overwrites the listed ones; a file it did not write is never removed or overwritten, and a folder
``OUTPUT/<stage>`` that exists but was not created by the engine is left alone (the stage is not published
there, with a warning saying what to do).
"""
from __future__ import annotations

import os
import shutil
import uuid

from . import registry
from .errors import CorruptEntry, UserError, warn_once
from .plan import Plan
from .store import read_checked_json, write_checked_json

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


def published_record(out_root: str) -> dict[str, list[str]]:
    """{stage: [paths relative to ``out_root``]} the engine published there (empty when there is none)."""
    rec = read_checked_json(os.path.join(out_root, PUBLISHED_NAME),
                            "its folders are treated as not written by the engine", default={})
    stages = rec.get("stages", {}) if isinstance(rec, dict) else {}
    return {k: [p for p in v if isinstance(p, str)] for k, v in stages.items() if isinstance(v, list)}


def _save_record(out_root: str, owned: dict[str, list[str]]) -> None:
    write_checked_json(os.path.join(out_root, PUBLISHED_NAME), {"stages": {k: sorted(v) for k, v in owned.items()}})


def publish(plan: Plan, log, verified: dict[str, dict[str, str]] | None = None) -> list[str]:
    """Copy the files of every file-writing stage from the cache to ``<output>/<stage>/`` (per-item stages:
    ``<output>/<stage>/<item>/``); a stage is published only when all its tasks are stored.

    verified: {task key: {relative path: stored file}} from :func:`verify_published` (checked again if absent).
    Returns the absolute paths written. Raises CorruptEntry when a stored file fails its checksum, and
    UserError when the output folder cannot be written.
    """
    out_root = plan.pipeline.output_dir
    try:
        return _publish(plan, out_root, verified or {})
    except OSError as exc:
        raise UserError(f"cannot write the output folder {out_root}: {exc.strerror or exc}"
                        + (f" ({exc.filename})" if exc.filename else ""),
                        fix="make it writable or publish elsewhere with --out FOLDER; every result is stored in "
                            "the cache, so the next run only copies the files") from None


def _publish(plan: Plan, out_root: str, verified: dict[str, dict[str, str]]) -> list[str]:
    owned = published_record(out_root)
    written: list[str] = []
    for name in file_stages(plan):
        sp = plan.stages[name]
        if not all(plan.store.has(t.key) for t in sp.tasks):
            continue
        target = os.path.join(out_root, name)
        if name not in owned and os.path.isdir(target) and os.listdir(target):
            warn_once(f"{target} exists and was not written by the engine: stage '{name}' is not published "
                      "there (move that folder away, or publish elsewhere with --out FOLDER)")
            continue
        if os.path.lexists(target) and not os.path.isdir(target):
            warn_once(f"{target} exists and is not a folder: stage '{name}' is not published")
            continue
        new: dict[str, str] = {}
        for t in sp.tasks:
            files = verified[t.key] if t.key in verified else plan.store.verify_files(t.key)
            base = os.path.join(name, t.label) if sp.spec.fanout == "item" else name
            for rel, src in files.items():
                rel = os.path.normpath(os.path.join(base, rel))
                if rel.split(os.sep)[0] != name:
                    raise CorruptEntry(t.key, f"stored file path {rel!r} leaves the stage's folder")
                new[rel] = src
        before = set(owned.get(name, []))
        owned[name] = sorted(before | set(new))  # recorded first: an interrupted publish still knows its files
        os.makedirs(out_root, exist_ok=True)
        _save_record(out_root, owned)
        for rel in sorted(before - set(new)):
            _remove_published(out_root, rel, target)
        kept = []
        for rel, src in sorted(new.items()):
            dst = os.path.join(out_root, rel)
            if os.path.lexists(dst) and rel not in before:
                warn_once(f"{dst} exists and was not written by the engine: left as it is (the stage's version "
                          f"is in the cache; remove the file to publish it)")
                continue
            _copy_atomic(src, dst)
            kept.append(rel)
            written.append(dst)
        owned[name] = sorted(kept)
        _save_record(out_root, owned)
    return written


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
