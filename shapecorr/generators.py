"""Generators: functions that write a dataset folder the pipeline then reads like user data."""
from __future__ import annotations

from corr_core.generate import write_chair_collection, write_humanoid_dataset
from corr_core.generate.humanoid import REMESH_KINDS
from corr_core.generate.tables import write_table_collection

from stages.registry import register


def _at_least(minimum: int, **values: int) -> None:
    """ValueError naming the first of ``values`` (param name -> value) below ``minimum``."""
    for name, v in values.items():
        if v < minimum:
            raise ValueError(f"parameter '{name}' = {v}: must be at least {minimum}")


def _check_chairs(*, n: int, seed: int, views: int, continuous: bool = False) -> None:
    _at_least(1, n=n, views=views)


def _check_tables(*, n: int, seed: int, views: int, n_chairs: int = 0, continuous: bool = True) -> None:
    _at_least(1, n=n, views=views)
    _at_least(0, n_chairs=n_chairs)


def _check_humanoid(*, n_poses: int, seed: int, vary_bodies: bool = False, remeshed: list = ()) -> None:
    _at_least(1, n_poses=n_poses)
    bad = [k for k in remeshed if k not in REMESH_KINDS]
    if bad:
        raise ValueError(f"parameter 'remeshed' = {list(remeshed)}: unknown kinds {bad}; use {list(REMESH_KINDS)}")
    if len(remeshed) > n_poses:
        raise ValueError(f"parameter 'remeshed' = {list(remeshed)}: at most n_poses = {n_poses} kinds")


@register("generate.chairs", kind="generator", validate=_check_chairs)
def chairs(*, n: int = 24, seed: int = 0, views: int = 16, continuous: bool = False, out_dir: str) -> None:
    """A collection of ``n`` procedural chairs (NNN.obj) at known random azimuths (ground_truth.csv): whole
    view steps, or any angle with ``continuous`` (azimuth_deg is then the exact angle)."""
    write_chair_collection(out_dir, n=n, seed=seed, views=views, continuous=continuous)


@register("generate.tables", kind="generator", validate=_check_tables)
def tables(*, n: int = 12, seed: int = 0, views: int = 16, n_chairs: int = 0, continuous: bool = True,
           out_dir: str) -> None:
    """``n`` procedural tables (round, square, rectangular in turn: symmetry order 0, 4, 2) then ``n_chairs``
    chairs, at known azimuths; ground_truth.csv has kind and symmetry_order columns."""
    write_table_collection(out_dir, n=n, seed=seed, views=views, n_chairs=n_chairs, continuous=continuous)


@register("generate.humanoid", kind="generator", validate=_check_humanoid)
def humanoid(*, n_poses: int = 6, seed: int = 0, vary_bodies: bool = False, remeshed: list = (),
             out_dir: str) -> None:
    """A posed humanoid in the course's SCAPE layout: meshes/template, meshes/test, landmark files.
    ``vary_bodies``: each test mesh is another person too (limb lengths, girth, proportions; same faces).
    ``remeshed``: kinds ("subdivided", "decimated") of extra test meshes with other connectivity, each with
    ``ground_truth/<mesh>.txt`` and ``landmarks/<mesh>.txt``."""
    write_humanoid_dataset(out_dir, n_poses=n_poses, seed=seed, vary_bodies=vary_bodies, remeshed=tuple(remeshed))
