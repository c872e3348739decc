"""Where each mesh's landmarks come from: the shared landmark file (the course layout: the template's vertex
ids, valid on every mesh numbered like it) or a per-mesh file ``landmarks/<mesh>.txt``; used by the course
stages (``shapecorr.correspondence``) and the dense ones (``shapecorr.dense``)."""
from __future__ import annotations

import os

import numpy as np

from corr_core.correspondence.landmarks import read_landmarks, subset_positions
from corr_core.correspondence.measures import numbering_problem
from corr_core.geometry.intrinsic import IntrinsicMesh


def _landmarks(path: str, n_vertices: int | None = None) -> tuple[np.ndarray, list[str]]:
    ids, names = read_landmarks(path, n_vertices=n_vertices)
    return np.asarray(ids, dtype=np.int64), list(names)


def sparse_positions(all_path: str, sparse_path: str, n_vertices: int | None = None) -> np.ndarray:
    """Positions of the sparse landmarks within the full landmark list: (k,) int."""
    ids, _ = _landmarks(all_path, n_vertices)
    sids, _ = _landmarks(sparse_path, n_vertices)
    return subset_positions(ids, sids, subset_name=sparse_path, full_name=all_path)


def _landmarks_on(mesh: dict, path: str) -> np.ndarray:
    """(L,) int landmark vertex ids of ``path``, checked to lie on the mesh's kept component (an error naming
    the landmark, the landmark file and the mesh file otherwise)."""
    ids, names = _landmarks(path, len(mesh["V"]))
    IntrinsicMesh(mesh["V"], mesh["F"]).to_sub(
        ids, what="landmark", names=names, source=f"{os.path.basename(path)} on {mesh.get('name', 'the mesh')}")
    return ids


def own_landmark_file(landmark_files, mesh_name: str) -> str | None:
    """``<landmark_files>/<mesh stem>.txt`` when that folder and file exist (per-mesh landmarks), else None."""
    if not landmark_files:
        return None
    path = os.path.join(landmark_files, os.path.splitext(os.path.basename(mesh_name))[0] + ".txt")
    return path if os.path.isfile(path) else None


def _ordered_like(path: str, mesh: dict, names: list[str]) -> np.ndarray:
    """Ids of a per-mesh landmark file in the order of ``names`` (the shared file's): by name, or in file order
    when the file has bare ids (as many as names)."""
    ids, own_names = _landmarks(path, len(mesh["V"]))
    by_name = dict(zip(own_names, ids.tolist()))
    if set(own_names) >= set(names):
        return np.asarray([by_name[n] for n in names], dtype=np.int64)
    if len(ids) == len(names) and all(n == str(v) for n, v in zip(own_names, ids)):
        return ids
    missing = [n for n in names if n not in by_name]
    raise ValueError(f"{path}: lacks the landmarks {missing} of the template's landmark file; list every one "
                     "as 'vid,Name' (names as in the template's file)")


def numbered_like_template(mesh: dict, template_mesh: dict | None) -> str | None:
    """Why the template's vertex ids do not name the same points on ``mesh``, or None when they do: the
    triangles of the kept components (``corr.mesh``'s "F": after repair, so vertices no face uses do not count)
    are the same (``measures.numbering_problem``). A vertex count alone never decides. No template: None."""
    if template_mesh is None:
        return None
    return numbering_problem(template_mesh["F"], mesh["F"], len(template_mesh["V"]), len(mesh["V"]))


def mesh_landmarks(mesh: dict, landmarks: str, landmark_files=None, template_mesh: dict | None = None
                   ) -> tuple[np.ndarray | None, str]:
    """This mesh's landmark ids in the order of the shared file ``landmarks``, and where they come from.

    ``landmark_files/<mesh>.txt`` when present ("own"); else the shared file ("shared"), which names the
    template's vertex ids and so applies only to a mesh numbered like the template: the same triangles
    (``numbered_like_template``; the course layout). Any other mesh, even one with the template's vertex count
    (e.g. its vertices in another order), has none: (None, why). Without ``template_mesh`` the shared file is
    taken as it is (the matchers then compare ``triangles_key``). Ids are checked to lie on the mesh's kept
    component. Returns: ((L,) int64 or None, "own" | "shared" | why).
    """
    own = own_landmark_file(landmark_files, mesh.get("name", ""))
    if own:
        ids = _ordered_like(own, mesh, _landmarks(landmarks)[1])
        IntrinsicMesh(mesh["V"], mesh["F"]).to_sub(ids, what="landmark", source=f"{own} on {mesh.get('name')}")
        return ids, "own"
    problem = numbered_like_template(mesh, template_mesh)
    if problem is None:
        return _landmarks_on(mesh, landmarks), "shared"
    stem = os.path.splitext(mesh.get("name", "mesh"))[0]
    return None, (f"no landmarks on {stem}: {problem}; {os.path.basename(landmarks)} (the template's vertex ids) "
                  f"does not apply and landmarks/{stem}.txt is not given")


def no_landmarks_result(mesh: dict, why: str) -> dict:
    """The result of a per-mesh landmark stage for a mesh without landmarks (the matchers skip it)."""
    return {"no_landmarks": why, "n_vertices": len(mesh["V"])}
