"""Procedural articulated humanoid: a closed, left/right symmetric surface mesh posed with the same connectivity.

Frame of the rest pose: y up (feet at y ~ 0, head top at y ~ 1.76, units ~ metres), the body faces +z, the
person's LEFT side is +x (names "Left ..." are at x > 0). Rest pose: standing, arms 35 degrees below horizontal.

Construction, one module each: a skeleton of joints and its bones (``rig``); the surface is the zero level set of
a smooth union (polynomial smooth-min) of round cones / ellipsoids (``surface``). The x >= 0 half is meshed with
``skimage.measure.marching_cubes`` (its flat cap on the midplane is cut off) and glued to its mirror image, so
the mesh is exactly left/right symmetric in vertices and connectivity; vertices are then relaxed tangentially and
projected back onto the implicit surface (better triangles; mirror pairs kept exact) (``meshing``). Poses use
linear blend skinning with weights diffused over the surface from a nearest-bone labelling, so every pose has the
same vertices and faces and vertex i matches vertex i (near-isometric; stretch only near joints) (``posing``).
Other people: per-bone proportions blended with the same weights (``bodies``). Named landmarks (``landmarks``),
re-triangulated copies with their true map (``connectivity``), and the dataset in memory and on disk
(``dataset``).
"""
from corr_core.generate.humanoid.bodies import BODY_RANGES, neutral_body, random_body, shape_body
from corr_core.generate.humanoid.connectivity import REMESH_KINDS, remesh, subdivide_midpoint
from corr_core.generate.humanoid.dataset import make_humanoid_dataset, write_humanoid_dataset
from corr_core.generate.humanoid.landmarks import (LANDMARK_NAMES, SPARSE_LANDMARK_NAMES, landmark_targets,
                                                   landmark_vertices)
from corr_core.generate.humanoid.meshing import DEFAULT_GRID_STEP, make_humanoid_rest, mirror_pairs
from corr_core.generate.humanoid.posing import pose_mesh, random_pose, skinning_weights
from corr_core.generate.humanoid.rig import ARM_DROP_DEG, skeleton
from corr_core.generate.humanoid.surface import body_sdf

__all__ = ["ARM_DROP_DEG", "BODY_RANGES", "DEFAULT_GRID_STEP", "LANDMARK_NAMES", "REMESH_KINDS",
           "SPARSE_LANDMARK_NAMES", "body_sdf", "landmark_targets", "landmark_vertices", "make_humanoid_dataset",
           "make_humanoid_rest", "mirror_pairs", "neutral_body", "pose_mesh", "random_body", "random_pose",
           "remesh", "shape_body", "skeleton", "skinning_weights", "subdivide_midpoint", "write_humanoid_dataset"]
