"""The project's own default data, generated deterministically from a seed (no downloads).

- ``chairs``: a collection of varied procedural chairs, each rotated about +y by a known random azimuth
  (problem 1, joint alignment), with ``ground_truth.csv``.
- ``humanoid``: an articulated, left/right symmetric humanoid surface mesh in several poses with identical
  connectivity and named landmarks, in the course's SCAPE layout (problem 2, landmark correspondence).
- ``defects``: defects of published meshes made on purpose (a seam cut, fins on non-manifold edges) for the tests
  and benchmarks of the repair and the dense maps.

See docs/generated_data.md for the conventions.
"""
from __future__ import annotations

import os
from pathlib import Path

from corr_core.generate.chairs import canonical_chair, make_chair, write_chair_collection
from corr_core.generate.humanoid import make_humanoid_dataset, make_humanoid_rest, write_humanoid_dataset

__all__ = ["make_chair", "canonical_chair", "write_chair_collection", "make_humanoid_rest",
           "make_humanoid_dataset", "write_humanoid_dataset", "write_default_data"]


def write_default_data(out_dir: str | os.PathLike, *, seed: int = 0, n_chairs: int = 24, views: int = 16,
                       n_poses: int = 6) -> dict:
    """Write both default data sets: ``out_dir/chairs`` (chair collection) and ``out_dir/scape`` (humanoid).

    Returns {"chairs": <write_chair_collection result>, "scape": <write_humanoid_dataset result>}.
    """
    out = Path(out_dir)
    return {"chairs": write_chair_collection(out / "chairs", n=n_chairs, seed=seed, views=views),
            "scape": write_humanoid_dataset(out / "scape", n_poses=n_poses, seed=seed)}
