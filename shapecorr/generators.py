"""Generators: functions that write a dataset folder the pipeline then reads like user data."""
from __future__ import annotations

from corr_core.generate import write_chair_collection, write_humanoid_dataset

from stages.registry import register


@register("generate.chairs", kind="generator")
def chairs(*, n: int = 24, seed: int = 0, views: int = 16, out_dir: str) -> None:
    """A collection of ``n`` procedural chairs (NNN.obj) at known random azimuths (ground_truth.csv)."""
    write_chair_collection(out_dir, n=n, seed=seed, views=views)


@register("generate.humanoid", kind="generator")
def humanoid(*, n_poses: int = 6, seed: int = 0, out_dir: str) -> None:
    """A posed humanoid in the course's SCAPE layout: meshes/template, meshes/test, landmark files."""
    write_humanoid_dataset(out_dir, n_poses=n_poses, seed=seed)
