"""Triangle-mesh reading and writing that never reorders or merges vertices.

Vertex ``i`` of the file is row ``i`` of ``V``: ground truth such as "vertex i matches vertex i" survives.
Polygons are fan-triangulated. Supported: OBJ, OFF, PLY (ASCII and binary little/big endian).
"""
from __future__ import annotations

import os
import struct

import numpy as np


class MeshError(ValueError):
    """A mesh file that cannot be used; the message names the file and the problem."""


def load_mesh(path: str | os.PathLike, require_faces: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh.

    Args:
        path: an ``.obj``, ``.off`` or ``.ply`` file.
        require_faces: raise ``MeshError`` when the file has no faces.
    Returns:
        V: (n, 3) float64 vertex positions, in file order.
        F: (m, 3) int64 triangle vertex indices (0-based).
    Raises:
        MeshError: missing file, unknown format, parse error, NaN/inf coordinates, out-of-range indices,
        or (with ``require_faces``) no faces.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise MeshError(f"{path}: mesh file not found")
    ext = os.path.splitext(path)[1].lower()
    try:
        if ext == ".obj":
            V, F = _read_obj(path)
        elif ext == ".off":
            V, F = _read_off(path)
        elif ext == ".ply":
            V, F = _read_ply(path)
        else:
            raise MeshError(f"{path}: unknown mesh format '{ext}' (use .obj, .off or .ply)")
    except MeshError:
        raise
    except (ValueError, IndexError, struct.error, UnicodeDecodeError) as exc:
        raise MeshError(f"{path}: cannot parse mesh ({exc})") from exc
    check_mesh(V, F, name=path, require_faces=require_faces)
    return V, F


def check_mesh(V: np.ndarray, F: np.ndarray, name: str = "mesh", require_faces: bool = True) -> None:
    """Raise ``MeshError`` naming ``name`` if ``V`` (n,3) / ``F`` (m,3) are not a usable triangle mesh."""
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
        raise MeshError(f"{name}: mesh has no vertices")
    if not np.all(np.isfinite(V)):
        bad = int(np.flatnonzero(~np.isfinite(V).all(axis=1))[0])
        raise MeshError(f"{name}: vertex {bad} has a NaN or infinite coordinate; repair or remove the mesh")
    if require_faces and len(F) == 0:
        raise MeshError(f"{name}: mesh has no faces (a point cloud?); a triangle mesh is required")
    if len(F) and (F.min() < 0 or F.max() >= len(V)):
        raise MeshError(f"{name}: a face refers to a vertex outside 0..{len(V) - 1}")


def _fan(poly: list[int]) -> list[tuple[int, int, int]]:
    return [(poly[0], poly[k], poly[k + 1]) for k in range(1, len(poly) - 1)]


def _read_obj(path: str) -> tuple[np.ndarray, np.ndarray]:
    verts: list[list[float]] = []
    faces: list[tuple[int, int, int]] = []
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if line.startswith("v "):
                parts = line.split()
                verts.append([float(parts[1]), float(parts[2]), float(parts[3])])
            elif line.startswith("f "):
                idx = []
                for tok in line.split()[1:]:
                    i = int(tok.split("/")[0])
                    idx.append(i - 1 if i > 0 else len(verts) + i)
                faces.extend(_fan(idx))
    return np.asarray(verts, dtype=np.float64).reshape(-1, 3), np.asarray(faces, dtype=np.int64).reshape(-1, 3)


def _tokens(path: str):
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        for line in fh:
            line = line.split("#", 1)[0]
            yield from line.split()


def _read_off(path: str) -> tuple[np.ndarray, np.ndarray]:
    tok = _tokens(path)
    head = next(tok)
    if not head.endswith("OFF"):
        raise MeshError(f"{path}: not an OFF file (first token '{head}')")
    nv, nf, _ = int(next(tok)), int(next(tok)), int(next(tok))
    V = np.array([[float(next(tok)) for _ in range(3)] for _ in range(nv)], dtype=np.float64).reshape(-1, 3)
    faces: list[tuple[int, int, int]] = []
    for _ in range(nf):
        k = int(next(tok))
        faces.extend(_fan([int(next(tok)) for _ in range(k)]))
    return V, np.asarray(faces, dtype=np.int64).reshape(-1, 3)


_PLY_TYPES = {"char": "b", "int8": "b", "uchar": "B", "uint8": "B", "short": "h", "int16": "h",
              "ushort": "H", "uint16": "H", "int": "i", "int32": "i", "uint": "I", "uint32": "I",
              "float": "f", "float32": "f", "double": "d", "float64": "d"}


def _read_ply(path: str) -> tuple[np.ndarray, np.ndarray]:
    with open(path, "rb") as fh:
        if fh.readline().strip() != b"ply":
            raise MeshError(f"{path}: not a PLY file")
        fmt, elements = None, []
        while True:
            line = fh.readline()
            if not line:
                raise MeshError(f"{path}: PLY header has no end_header")
            parts = line.decode("ascii", "replace").split()
            if not parts:
                continue
            if parts[0] == "format":
                fmt = parts[1]
            elif parts[0] == "element":
                elements.append((parts[1], int(parts[2]), []))
            elif parts[0] == "property":
                elements[-1][2].append(parts[1:])
            elif parts[0] == "end_header":
                break
        body = fh.read()
    V = np.zeros((0, 3))
    faces: list[tuple[int, int, int]] = []
    if fmt == "ascii":
        tok = iter(body.decode("ascii", "replace").split())
        read = lambda t: float(next(tok)) if t in "fd" else int(next(tok))  # noqa: E731
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        offset = [0]

        def read(t: str):
            val = struct.unpack_from(order + t, body, offset[0])[0]
            offset[0] += struct.calcsize(t)
            return val
    for name, count, props in elements:
        rows = []
        for _ in range(count):
            row = {}
            for prop in props:
                if prop[0] == "list":
                    n = read(_PLY_TYPES[prop[1]])
                    row[prop[3]] = [read(_PLY_TYPES[prop[2]]) for _ in range(int(n))]
                else:
                    row[prop[1]] = read(_PLY_TYPES[prop[0]])
            rows.append(row)
        if name == "vertex":
            V = np.array([[r["x"], r["y"], r["z"]] for r in rows], dtype=np.float64).reshape(-1, 3)
        elif name == "face":
            for r in rows:
                poly = r.get("vertex_indices", r.get("vertex_index"))
                faces.extend(_fan([int(i) for i in poly]))
    return V, np.asarray(faces, dtype=np.int64).reshape(-1, 3)


def save_obj(path: str | os.PathLike, V: np.ndarray, F: np.ndarray) -> None:
    """Write ``V`` (n,3) float and ``F`` (m,3) int (0-based) as an OBJ file, vertex order preserved."""
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("".join(f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in V))
        fh.write("".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F))


def surface_centroid(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(3,) area-weighted centroid of the triangles: independent of tessellation and of rotations."""
    T = V[F]
    area = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    if area.sum() <= 0:
        return V.mean(axis=0)
    return (area[:, None] * T.mean(axis=1)).sum(axis=0) / area.sum()


def normalize_mesh(V: np.ndarray, center: str = "bbox", F: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray, float]:
    """Centre a shape at the origin and scale it to unit radius.

    Args:
        V: (n, 3) vertex positions.
        center: "bbox" (centre of the axis-aligned bounding box), "mean" (vertex centroid) or "area"
            (area-weighted surface centroid, needs ``F``; commutes with rotations and does not depend on the
            tessellation, so a rotated copy of a shape normalizes to the rotated normalized shape).
        F: (m, 3) faces, for center="area".
    Returns:
        Vn: (n, 3) normalized positions, max ||Vn_i|| == 1.
        c: (3,) the centre that was subtracted.
        s: the scale that was divided by (the radius about ``c``).
    """
    if center == "bbox":
        c = 0.5 * (V.min(axis=0) + V.max(axis=0))
    elif center == "mean":
        c = V.mean(axis=0)
    elif center == "area":
        if F is None:
            raise ValueError("center='area' needs the faces F")
        c = surface_centroid(V, F)
    else:
        raise ValueError(f"center must be 'bbox', 'mean' or 'area', got {center!r}")
    r = float(np.linalg.norm(V - c, axis=1).max())
    if not np.isfinite(r) or r <= 0:
        raise MeshError("cannot normalize a mesh whose vertices all coincide")
    return (V - c) / r, c, r
