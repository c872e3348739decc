"""``gc``: remove cache entries that none of the given pipelines reaches, and temporary leftovers; by default only
entries that belong to those pipelines (``--all``: also other pipelines' and unrecorded ones)."""
from __future__ import annotations

import os

from .cache import open_store
from .cache_root import CACHE_MARKER, KEY_PATTERN, cache_location
from .checksums import read_checked_json
from .errors import UserError
from .execute import clean_tmp
from .plan import plan_pipeline
from .record import legacy_pipeline_id, owners, pipeline_id, sweep_record_files
from .seal import SEAL_NAME
from .store import disk_usage
from .sweep import parse_grid


def gc(paths: list[str], cache_dir: str | None = None, dry: bool = False, keep_sweeps: bool = True,
       everything: bool = False) -> dict:
    """Remove cache entries that none of the given pipelines (current configuration, and their recorded
    sweeps when ``keep_sweeps``) reaches; also removes temporary leftovers.

    By default only what belongs to the given pipelines is removed: entries (and generated datasets) that their
    recorded runs and sweeps reference (``cache/runs``, see stages.record.owners) and no other pipeline's do, so
    pipelines sharing the cache never lose each other's results. ``everything`` (``--all``) also removes the
    entries of other pipelines and those no recorded run references.

    Returns {"kept", "removed", "generated_removed", "bytes_freed", "dry_run", "entries": [{"key", "stage",
    "label", "pipelines", "bytes"}] removed, "generated": [{"name", "pipelines"}] removed, "others_kept": entries
    kept because they belong to other pipelines or to none recorded}.
    """
    reachable: set[str] = set()
    store = None
    generated_keep: set[str] = set()
    mine: set[str] = set()  # the pipeline ids of the given pipelines (also their ids in older caches)
    for p in paths:
        plan = plan_pipeline(p, (), cache_dir, None, quiet=True)
        store = plan.store
        mine |= {pipeline_id(plan), legacy_pipeline_id(plan)}
        if not store.exists():  # no cache yet: nothing to remove
            continue
        _check_plannable(p, plan, dry)
        reachable |= {t.key for t in plan.tasks()}
        generated_keep |= {os.path.basename(g.path) for g in plan.pipeline.generated.values()}
        if keep_sweeps:
            reachable |= _sweep_keys(p, plan, cache_dir)
    store = store or open_store(cache_location(cache_dir or "cache"))
    empty = {"kept": 0, "removed": 0, "generated_removed": 0, "bytes_freed": 0, "dry_run": dry, "entries": [],
             "generated": [], "others_kept": 0}
    if not store.exists():
        return empty
    if not store.is_marked():
        raise UserError(f"{store.location} has no {CACHE_MARKER} marker: it is not a cache the engine created, so gc "
                        "removes nothing there", fix="pass the cache folder of your pipelines with --cache")
    known = owners(store.root)
    by_key: dict[str, list[str]] = {}
    for pid, owner in known.items():
        for k in owner.keys:
            by_key.setdefault(k, []).append(pid)
    unreachable = [k for k in store.all_keys() if k not in reachable]
    removed = [k for k in unreachable if everything or _only_mine(by_key.get(k, []), mine)]
    entries, freed = [], 0
    for k in removed:
        size = store.entry_bytes(k)
        info = (store.manifest(k) or {}).get("info", {})
        entries.append({"key": k, "stage": info.get("stage", "?"), "label": info.get("label", ""),
                        "pipelines": _labels(by_key.get(k, []), known), "bytes": size})
        freed += size
        if not dry:
            store.remove(k)
    for what, size in store.stale_writes():  # object stores: data of writes no manifest names (lost races)
        freed += size
        if not dry:
            store.remove_stale(what)
    gen_owners: dict[str, list[str]] = {}
    for pid, owner in known.items():
        for g in owner.generated:
            gen_owners.setdefault(g, []).append(pid)
    gen_dir = os.path.join(store.root, "generated")
    gen_removed = [g for g in (sorted(os.listdir(gen_dir)) if os.path.isdir(gen_dir) else [])
                   if g not in generated_keep and KEY_PATTERN.match(g)
                   and os.path.isfile(os.path.join(gen_dir, g, SEAL_NAME))  # only datasets the engine wrote
                   and (everything or _only_mine(gen_owners.get(g, []), mine))]
    for g in gen_removed:
        freed += disk_usage(os.path.join(gen_dir, g))
        if not dry:
            store.discard(os.path.join(gen_dir, g))
    if not dry:
        clean_tmp(store, older_than_s=0)
    return {"kept": len(store.all_keys()) if not dry else len(store.all_keys()) - len(removed),
            "removed": len(removed), "generated_removed": len(gen_removed), "bytes_freed": freed, "dry_run": dry,
            "entries": entries, "generated": [{"name": g, "pipelines": _labels(gen_owners.get(g, []), known)}
                                              for g in gen_removed],
            "others_kept": len(unreachable) - len(removed)}


def _check_plannable(path: str, plan, dry: bool) -> None:
    """UserError when the task keys of ``plan`` are not all known yet (so gc cannot tell what it reaches)."""
    if plan.pending_generated and not dry:  # its task keys are not known before the data exists
        raise UserError(f"{path}: generated dataset(s) {', '.join(sorted(plan.pending_generated))} not written yet, "
                        "so gc cannot tell which entries this pipeline reaches; it removes nothing",
                        fix=f"run it first: python -m stages run {path}")
    waiting = sorted({sp.waiting for sp in plan.stages.values() if sp.waiting})
    if waiting and not dry:  # the tasks of a pair stage on a candidate graph are not known before its candidates
        raise UserError(f"{path}: stage(s) wait for candidates stage(s) {', '.join(waiting)} not computed yet, so gc "
                        "cannot tell which entries this pipeline reaches; it removes nothing",
                        fix=f"run it first: python -m stages run {path}")


def _sweep_keys(path: str, plan, cache_dir: str | None) -> set[str]:
    """The task keys of every point of the recorded sweeps of ``plan``'s pipeline."""
    keys: set[str] = set()
    for fn in sweep_record_files(plan):
        sw = read_checked_json(fn, "its results are not kept by gc")
        if sw is None or not isinstance(sw.get("grid"), list):
            continue
        for point in parse_grid(sw["grid"]):
            try:
                pl = plan_pipeline(path, sw.get("overrides", []) + point, cache_dir, None, quiet=True)
                keys |= {t.key for t in pl.tasks()}
            except Exception:
                pass
    return keys


def _only_mine(pids: list[str], mine: set[str]) -> bool:
    """True when an entry's recorded pipelines ``pids`` are all among the given pipelines (and there is one)."""
    return bool(pids) and set(pids) <= mine


def _labels(pids: list[str], known: dict) -> list[str]:
    """The pipelines of an entry as ``name (file)``, or ["no recorded pipeline"]."""
    return sorted({known[p].label for p in pids}) or ["no recorded pipeline"]
