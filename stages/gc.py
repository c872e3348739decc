"""``gc``: remove cache entries that none of the given pipelines reaches, and temporary leftovers."""
from __future__ import annotations

import os

from .errors import UserError
from .execute import clean_tmp
from .plan import plan_pipeline
from .record import pipeline_id
from .store import CACHE_MARKER, KEY_PATTERN, SEAL_NAME, Store, _disk_usage, cache_location, read_checked_json
from .sweep import parse_grid


def gc(paths: list[str], cache_dir: str | None = None, dry: bool = False, keep_sweeps: bool = True) -> dict:
    """Remove cache entries that none of the given pipelines (current configuration, and their recorded
    sweeps when ``keep_sweeps``) reaches; also removes temporary leftovers.

    Returns {"kept", "removed", "generated_removed", "bytes_freed", "dry_run"}.
    """
    reachable: set[str] = set()
    store = None
    generated_keep: set[str] = set()
    for p in paths:
        plan = plan_pipeline(p, (), cache_dir, None, quiet=True)
        store = plan.store
        if not store.exists():  # no cache yet: nothing to remove
            continue
        if plan.pending_generated and not dry:  # its task keys are not known before the data exists
            raise UserError(f"{p}: generated dataset(s) {', '.join(sorted(plan.pending_generated))} not written yet, "
                            "so gc cannot tell which entries this pipeline reaches; it removes nothing",
                            fix=f"run it first: python -m stages run {p}")
        waiting = sorted({sp.waiting for sp in plan.stages.values() if sp.waiting})
        if waiting and not dry:  # the tasks of a pair stage on a candidate graph are not known before its candidates
            raise UserError(f"{p}: stage(s) wait for candidates stage(s) {', '.join(waiting)} not computed yet, so gc "
                            "cannot tell which entries this pipeline reaches; it removes nothing",
                            fix=f"run it first: python -m stages run {p}")
        reachable |= {t.key for t in plan.tasks()}
        generated_keep |= {os.path.basename(g.path) for g in plan.pipeline.generated.values()}
        if keep_sweeps:
            sweeps_dir = os.path.join(store.root, "sweeps")
            for fn in os.listdir(sweeps_dir) if os.path.isdir(sweeps_dir) else []:
                if fn.startswith(pipeline_id(p)):
                    sw = read_checked_json(os.path.join(sweeps_dir, fn), "its results are not kept by gc")
                    if sw is None or not isinstance(sw.get("grid"), list):
                        continue
                    for point in parse_grid(sw["grid"]):
                        try:
                            pl = plan_pipeline(p, sw.get("overrides", []) + point, cache_dir, None, quiet=True)
                            reachable |= {t.key for t in pl.tasks()}
                        except Exception:
                            pass
    store = store or Store(cache_location(cache_dir or "cache"))
    if not store.exists():
        return {"kept": 0, "removed": 0, "generated_removed": 0, "bytes_freed": 0, "dry_run": dry}
    if not store.is_marked():
        raise UserError(f"{store.location} has no {CACHE_MARKER} marker: it is not a cache the engine created, so gc "
                        "removes nothing there", fix="pass the cache folder of your pipelines with --cache")
    removed = [k for k in store.all_keys() if k not in reachable]
    freed = 0
    for k in removed:
        freed += store.entry_bytes(k)
        if not dry:
            store.remove(k)
    for what, size in store.stale_writes():  # object stores: data of writes no manifest names (lost races)
        freed += size
        if not dry:
            store.remove_stale(what)
    gen_dir = os.path.join(store.root, "generated")
    gen_removed = [g for g in (os.listdir(gen_dir) if os.path.isdir(gen_dir) else [])
                   if g not in generated_keep and KEY_PATTERN.match(g)
                   and os.path.isfile(os.path.join(gen_dir, g, SEAL_NAME))]  # only datasets the engine wrote
    for g in gen_removed:
        freed += disk_usage(os.path.join(gen_dir, g))
        if not dry:
            store.discard(os.path.join(gen_dir, g))
    if not dry:
        clean_tmp(store, older_than_s=0)
    return {"kept": len(store.all_keys()) if not dry else len(store.all_keys()) - len(removed),
            "removed": len(removed), "generated_removed": len(gen_removed), "bytes_freed": freed, "dry_run": dry}


def disk_usage(path: str) -> int:
    """Bytes of all files under the local folder ``path`` (0 if it does not exist)."""
    return _disk_usage(path)
