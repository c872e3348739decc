"""A humanoid dataset: the rest mesh, posed (and reshaped) bodies and landmarks, in memory and in the course layout."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from corr_core.correspondence.landmarks import format_landmarks, write_landmarks
from corr_core.generate.humanoid.bodies import neutral_body, random_body, shape_body
from corr_core.generate.humanoid.connectivity import remesh
from corr_core.generate.humanoid.landmarks import LANDMARK_NAMES, SPARSE_LANDMARK_NAMES, landmark_vertices
from corr_core.generate.humanoid.meshing import DEFAULT_GRID_STEP, make_humanoid_rest
from corr_core.generate.humanoid.posing import pose_mesh, random_pose, skinning_weights
from corr_core.geometry.mesh_io import save_obj


def make_humanoid_dataset(*, n_poses: int = 6, seed: int = 0, vary_bodies: bool = False,
                          grid_step: float = DEFAULT_GRID_STEP):
    """Rest mesh, posed meshes and landmarks, in memory.

    vary_bodies: each posed mesh is also a different person (``random_body`` from
    ``np.random.default_rng([seed, 1])``, so the poses are those of ``vary_bodies=False``); the rest mesh stays
    the rest body. Same vertices and faces either way.
    grid_step: resolution of ``make_humanoid_rest`` (metres; the default gives 4691 vertices, 0.03 about 2,600).
    Returns: (V_rest (n,3), F (m,3), poses list of (n,3) arrays, pose parameters list of dicts,
    landmarks dict name -> vertex id, bodies list of dicts (all 1.0 without ``vary_bodies``)).
    """
    V, F = make_humanoid_rest(grid_step=grid_step)
    W, _ = skinning_weights(V, F)
    rng = np.random.default_rng(seed)
    params = [random_pose(rng) for _ in range(n_poses)]
    body_rng = np.random.default_rng([seed, 1])
    bodies = [random_body(body_rng) if vary_bodies else neutral_body() for _ in range(n_poses)]
    posed = []
    for pose, body in zip(params, bodies):
        Vb, Jb = shape_body(V, W, body) if vary_bodies else (V, None)
        posed.append(pose_mesh(Vb, W, pose, Jb))
    return V, F, posed, params, landmark_vertices(V), bodies


def write_humanoid_dataset(out_dir: str | os.PathLike, *, n_poses: int = 6, seed: int = 0, vary_bodies: bool = False,
                           remeshed: tuple[str, ...] | list[str] = (), grid_step: float = DEFAULT_GRID_STEP) -> dict:
    """Write the course layout: ``meshes/template/mesh000.obj`` (rest pose), ``meshes/test/meshNNN.obj``
    (NNN = 001..n_poses, random poses drawn from ``np.random.default_rng(seed)``), ``landmark_vids.txt`` and
    ``sparse_landmark_vids.txt`` (``vid,Name`` lines, 0-based). All meshes share faces; vertex i matches vertex i.

    vary_bodies: the test meshes are other people too (``make_humanoid_dataset``); same faces.
    remeshed: kinds (``REMESH_KINDS``); the k-th is written as ``meshes/test/mesh<n_poses+k>.obj``, pose k
    (1-based) re-triangulated by ``remesh`` (seed k), with its true map ``ground_truth/<mesh>.txt`` (one target
    vertex id per template vertex, a line each) and its landmarks ``landmarks/<mesh>.txt`` (``vid,Name``).
    grid_step: mesh resolution (``make_humanoid_dataset``); coarser is cheaper to process (tests).
    Returns (JSON-serialisable): {"out_dir", "template", "tests": [paths], "landmarks": {name: vid},
    "sparse_landmarks": {name: vid}, "n_vertices", "n_faces", "poses": [dict of joint angles in degrees],
    "bodies": [dict of body factors], "remeshed": {mesh: {"kind", "n_vertices"}}}.
    """
    out = Path(out_dir)
    (out / "meshes" / "template").mkdir(parents=True, exist_ok=True)
    (out / "meshes" / "test").mkdir(parents=True, exist_ok=True)
    V, F, posed, params, lms, bodies = make_humanoid_dataset(n_poses=n_poses, seed=seed, vary_bodies=vary_bodies,
                                                             grid_step=grid_step)
    if len(remeshed) > n_poses:
        raise ValueError(f"remeshed: {len(remeshed)} kinds but only {n_poses} poses to remesh")
    template = out / "meshes" / "template" / "mesh000.obj"
    save_obj(template, V, F)
    tests = []
    for i, Vp in enumerate(posed, start=1):
        path = out / "meshes" / "test" / f"mesh{i:03d}.obj"
        save_obj(path, Vp, F)
        tests.append(str(path))
    remeshed_info = {}
    for k, kind in enumerate(remeshed, start=1):
        name = f"mesh{n_poses + k:03d}"
        V2, F2, truth = remesh(posed[k - 1], F, kind, seed=k)
        save_obj(out / "meshes" / "test" / f"{name}.obj", V2, F2)
        for sub, text in (("ground_truth", "".join(f"{t}\n" for t in truth)),
                          ("landmarks", format_landmarks([truth[lms[n]] for n in LANDMARK_NAMES], LANDMARK_NAMES))):
            (out / sub).mkdir(exist_ok=True)
            (out / sub / f"{name}.txt").write_text(text)
        tests.append(str(out / "meshes" / "test" / f"{name}.obj"))
        remeshed_info[name] = {"kind": kind, "n_vertices": int(len(V2))}
    write_landmarks(out / "landmark_vids.txt", [lms[n] for n in LANDMARK_NAMES], LANDMARK_NAMES)
    sparse = {n: lms[n] for n in SPARSE_LANDMARK_NAMES}
    write_landmarks(out / "sparse_landmark_vids.txt", list(sparse.values()), list(sparse))
    return {"out_dir": str(out), "template": str(template), "tests": tests, "landmarks": lms,
            "sparse_landmarks": sparse, "n_vertices": int(len(V)), "n_faces": int(len(F)),
            "poses": [{k: float(v) for k, v in p.items()} for p in params], "bodies": bodies,
            "remeshed": remeshed_info}
