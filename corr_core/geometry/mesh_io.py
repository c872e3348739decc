"""Triangle-mesh reading and writing that never reorders or merges vertices.

Vertex ``i`` of the file is row ``i`` of ``V``: ground truth such as "vertex i matches vertex i" survives.
Polygons are fan-triangulated ``(p0, pk, pk+1)``.

Formats and readers:
- PLY (ASCII, binary little/big endian): meshio (trimesh 5.2 fails on binary PLY files that mix triangles and
  polygons). Faces come grouped by polygon size (triangles, quads, larger polygons), in file order within each.
- STL, GLB/GLTF: trimesh (``process=False``, so nothing is merged or reordered; a GLB/GLTF scene is flattened
  into one mesh with its node transforms applied, geometries in scene order). STL stores every triangle's
  corners separately; they are merged (first occurrence order), since STL has no vertex ids to keep.
- OBJ and OFF: a small reader here, because trimesh's OBJ loader splits vertices that carry several texture
  coordinates / normals (``f 1/1 ...`` vs ``f 1/2 ...``) and does not resolve negative indices, and its OFF
  loader fails on files mixing triangles and polygons: both would change vertex ids. OBJ: ``v`` and ``f`` lines
  (``f a``, ``f a/b``, ``f a//c``, ``f a/b/c``, negative = relative to the vertices read so far); ``vt``,
  ``vn``, materials, groups and objects are ignored (alignment and correspondence need geometry only). A file of
  only ``v x y z`` / ``f a b c`` lines is parsed in a few vectorized passes, to the same arrays.
"""
from __future__ import annotations

import os
import warnings

import numpy as np

from corr_core.geometry.primitives import surface_centroid

MESH_EXTENSIONS = (".obj", ".off", ".ply", ".stl", ".glb", ".gltf")


class MeshError(ValueError):
    """A mesh file that cannot be used; the message names the file, the problem and the fix."""


def counted(n, singular: str, plural: str | None = None) -> str:
    """``n`` with the noun in the right number, for messages: ``1 face``, ``4,780 duplicate faces``, ``2 vertices``."""
    n = int(n)
    return f"{n:,} {singular if n == 1 else (plural or singular + 's')}"


def load_mesh(path: str | os.PathLike, require_faces: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh, vertices in file order.

    Args:
        path: an ``.obj``, ``.off``, ``.ply``, ``.stl``, ``.glb`` or ``.gltf`` file.
        require_faces: raise ``MeshError`` when the file has no faces (False: a point cloud is fine).
    Returns:
        V: (n, 3) float64 vertex positions, in file order.
        F: (m, 3) int64 triangle vertex indices (0-based), polygons fan-triangulated, in file order (a PLY
            file mixing triangles and polygons: grouped by polygon size).
    Raises:
        MeshError naming the file: missing file, unknown format, parse error, no vertices, out-of-range
        indices, NaN/inf coordinates of a vertex that a face uses (of any vertex when there are no faces),
        or (with ``require_faces``) no faces.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise MeshError(f"{path}: mesh file not found")
    ext = os.path.splitext(path)[1].lower()
    if ext not in MESH_EXTENSIONS:
        raise MeshError(f"{path}: unknown mesh format '{ext}' (use {', '.join(MESH_EXTENSIONS)})")
    try:
        if ext == ".obj":
            V, F = _read_obj(path)
        elif ext == ".off":
            V, F = _read_off(path)
        elif ext == ".ply":
            V, F = _read_ply(path)
        else:
            V, F = _read_with_trimesh(path)
    except MeshError:
        raise
    except Exception as exc:  # parsers raise ValueError, IndexError, UnicodeDecodeError, struct/zlib errors...
        raise MeshError(f"{path}: cannot parse mesh ({type(exc).__name__}: {exc}); "
                        "check that the file is a complete, valid mesh") from exc
    check_mesh(V, F, name=path, require_faces=require_faces)
    return V, F


def check_mesh(V: np.ndarray, F: np.ndarray, name: str = "mesh", require_faces: bool = True) -> None:
    """Raise ``MeshError`` naming ``name`` if ``V`` (n,3) / ``F`` (m,3) are not a usable triangle mesh.

    Only vertices that a face uses must be finite (unused ones are ignored everywhere); without faces, all.
    """
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
        raise MeshError(f"{name}: mesh has no vertices (empty or not a mesh file)")
    if require_faces and len(F) == 0:
        raise MeshError(f"{name}: mesh has no faces (a point cloud?); a triangle mesh is required")
    if len(F) and (F.min() < 0 or F.max() >= len(V)):
        raise MeshError(f"{name}: a face refers to a vertex outside 0..{len(V) - 1}; the file is corrupt")
    used = np.unique(F) if len(F) else np.arange(len(V))
    bad = used[~np.isfinite(V[used]).all(axis=1)]
    if len(bad):
        raise MeshError(f"{name}: {counted(len(bad), 'vertex', 'vertices')} used by a face "
                        f"{'has' if len(bad) == 1 else 'have'} a NaN or infinite coordinate "
                        f"(first: vertex {int(bad[0])}); repair the file or remove the mesh")
    far = used[(np.abs(V[used]) > MAX_COORDINATE).any(axis=1)]
    if len(far):
        i = int(far[0])
        raise MeshError(f"{name}: vertex {i} (0-based: vertex number {i + 1} of the file) is out of range: "
                        f"({', '.join(f'{c:.3g}' for c in V[i])}), coordinates must be within +-{MAX_COORDINATE:g}"
                        f"{f' ({len(far)} such vertices)' if len(far) > 1 else ''}; repair the file or remove "
                        "the mesh")


MAX_COORDINATE = 1e12   # |x|, |y|, |z| of a vertex a face uses: beyond, areas and distances lose all precision


def _fan(poly: list[int]) -> list[tuple[int, int, int]]:
    return [(poly[0], poly[k], poly[k + 1]) for k in range(1, len(poly) - 1)]


def _as_arrays(verts, faces) -> tuple[np.ndarray, np.ndarray]:
    return (np.asarray(verts, dtype=np.float64).reshape(-1, 3), np.asarray(faces, dtype=np.int64).reshape(-1, 3))


def _obj_index(token: str, n_read: int, path: str, line_no: int) -> int:
    """0-based vertex index of one ``f`` token (``a``, ``a/b``, ``a//c``, ``a/b/c``; negative = relative)."""
    i = int(token.split("/", 1)[0])
    if i == 0:
        raise MeshError(f"{path}:{line_no}: OBJ face index 0 (OBJ indices start at 1)")
    return i - 1 if i > 0 else n_read + i


_OBJ_KEYWORDS = {b"v": 0, b"f": 1}


def _read_plain_obj(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """The common OBJ layout in a few vectorized passes, or None for anything else (the caller then reads the
    file line by line, which gives the same result, or the error message naming the line).

    Accepted: printable ASCII, spaces, tabs and ``\\n`` only; every non-blank line is ``v x y z`` or ``f a b c``
    (exactly four tokens, indices positive integers without ``/``), as ``save_obj`` and most exporters write.
    Numbers are converted by Python's ``float`` / ``int``, like the line reader, so the arrays are identical.
    """
    if not data:
        return None
    raw = np.frombuffer(data, np.uint8)
    space = (raw == 32) | (raw == 9)
    newline = raw == 10
    if not np.all(space | newline | ((raw > 32) & (raw < 127))):
        return None
    solid = ~(space | newline)
    starts = np.flatnonzero(solid & np.concatenate([[True], ~solid[:-1]]))  # first byte of every token
    tokens_per_line = np.bincount(np.cumsum(newline)[starts])
    if np.any((tokens_per_line != 0) & (tokens_per_line != 4)):
        return None
    tokens = data.split()
    keys = tokens[0::4]
    kinds = np.fromiter((_OBJ_KEYWORDS.get(k, 2) for k in keys), np.int8, len(keys))
    if np.any(kinds == 2):
        return None
    values = np.asarray(tokens, dtype=object).reshape(-1, 4)[:, 1:]
    try:
        V = np.array(list(map(float, values[kinds == 0].ravel())), np.float64).reshape(-1, 3)
        F = np.array(list(map(int, values[kinds == 1].ravel())), np.int64).reshape(-1, 3)
    except (ValueError, OverflowError):
        return None
    if F.size and F.min() < 1:  # 0 (an error) or relative indices: the line reader handles and names them
        return None
    return V, F - 1


def _read_obj(path: str) -> tuple[np.ndarray, np.ndarray]:
    """OBJ vertices and fan-triangulated faces: the plain layout vectorized, anything else line by line."""
    with open(path, "rb") as fh:
        plain = _read_plain_obj(fh.read())
    return plain if plain is not None else _read_obj_lines(path)


def _read_obj_lines(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Any OBJ file, line by line (see the module docstring); MeshError names the line it cannot read."""
    verts: list[list[float]] = []
    faces: list[tuple[int, int, int]] = []
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        for line_no, line in enumerate(fh, start=1):
            parts = line.split()
            if not parts:
                continue
            try:
                if parts[0] == "v":
                    verts.append([float(parts[1]), float(parts[2]), float(parts[3])])
                elif parts[0] == "f":
                    faces.extend(_fan([_obj_index(t, len(verts), path, line_no) for t in parts[1:]]))
            except MeshError:
                raise
            except (ValueError, IndexError) as exc:
                raise MeshError(f"{path}:{line_no}: cannot parse {line.strip()!r} ({exc})") from exc
    return _as_arrays(verts, faces)


def _tokens(path: str):
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        for line in fh:
            yield from line.split("#", 1)[0].split()


def _read_off(path: str) -> tuple[np.ndarray, np.ndarray]:
    tok = _tokens(path)
    head = next(tok, "")
    if not head.endswith("OFF"):
        raise MeshError(f"{path}: not an OFF file (first token '{head}')")
    try:
        nv, nf, _ = int(next(tok)), int(next(tok)), int(next(tok))
        V = [[float(next(tok)) for _ in range(3)] for _ in range(nv)]
        faces: list[tuple[int, int, int]] = []
        for _ in range(nf):
            k = int(next(tok))
            faces.extend(_fan([int(next(tok)) for _ in range(k)]))
    except StopIteration:
        raise MeshError(f"{path}: OFF file ends early (truncated?)") from None
    return _as_arrays(V, faces)


_SURFACE_CELLS = ("triangle", "quad", "polygon")


def _read_ply(path: str) -> tuple[np.ndarray, np.ndarray]:
    """PLY through meshio: points in file order, surface cells fan-triangulated block by block."""
    import meshio

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = meshio.read(path, file_format="ply")
    polygons = [np.asarray(block.data, dtype=np.int64) for block in mesh.cells
                if block.type.startswith(_SURFACE_CELLS)]
    return np.asarray(mesh.points, dtype=np.float64)[:, :3], _fan_blocks(polygons)


def _fan_blocks(polygons: list[np.ndarray]) -> np.ndarray:
    """(m,3) fan triangles of blocks of polygons (each (k, n) int), block after block, polygon by polygon."""
    out = [np.stack([P[:, [0, k, k + 1]] for k in range(1, P.shape[1] - 1)], axis=1).reshape(-1, 3)
           for P in polygons if P.ndim == 2 and P.shape[1] >= 3]
    return np.concatenate(out) if out else np.zeros((0, 3), dtype=np.int64)


def _read_with_trimesh(path: str) -> tuple[np.ndarray, np.ndarray]:
    """STL / GLB / GLTF through trimesh, without any processing (vertex order kept)."""
    import trimesh

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # trimesh warns about textures/materials it cannot resolve
        loaded = trimesh.load(path, process=False, maintain_order=True, force="mesh")
    V = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
    F = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    if path.lower().endswith(".stl") and len(F):
        V, F = _merge_stl_corners(V, F)
    return V, F


def _merge_stl_corners(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge exactly equal corner positions of an STL triangle soup, vertices in first-occurrence order."""
    _, first, inverse = np.unique(V, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty(len(first), dtype=np.int64)
    rank[order] = np.arange(len(first))
    return V[first[order]], rank[inverse.ravel()][F]


def save_obj(path: str | os.PathLike, V: np.ndarray, F: np.ndarray) -> None:
    """Write ``V`` (n,3) float and ``F`` (m,3) int (0-based) as an OBJ file, vertex order preserved.

    Coordinates as ``%.9g`` (float32 exactly, float64 to 9 significant digits), one %-formatting of the whole
    block: the bytes of a line-by-line f-string, in about a fifth of its time."""
    V, F = (np.asarray(a).reshape(0, 3) if np.size(a) == 0 else np.asarray(a) for a in (V, F))
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"save_obj {path}: V must be (n, 3) and F (m, 3), got {V.shape} and {F.shape}")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(("v %.9g %.9g %.9g\n" * len(V)) % tuple(V.ravel().tolist()))
        fh.write(("f %d %d %d\n" * len(F)) % tuple((F.astype(np.int64) + 1).ravel().tolist()))


def referenced_vertices(n_vertices: int, F: np.ndarray | None) -> np.ndarray:
    """(k,) int ids of the vertices some face uses, increasing; all ``n_vertices`` when F is None or empty."""
    if F is None or len(F) == 0:
        return np.arange(n_vertices)
    return np.unique(np.asarray(F))


def normalize_mesh(V: np.ndarray, center: str = "bbox", F: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray, float]:
    """Centre a shape at the origin and scale it to unit radius, from the vertices the faces use.

    Vertices no face uses (stray points in a scan, possibly far away or NaN) take no part in the centre or
    the scale: they are transformed like the others but can lie outside the unit ball.

    Args:
        V: (n, 3) vertex positions.
        center: "bbox" (centre of the axis-aligned bounding box), "mean" (vertex centroid) or "area"
            (area-weighted surface centroid, needs ``F``; commutes with rotations and does not depend on the
            tessellation, so a rotated copy of a shape normalizes to the rotated normalized shape).
        F: (m, 3) faces; None = every vertex counts (a point cloud).
    Returns:
        Vn: (n, 3) normalized positions, max ||Vn_i|| == 1 over referenced vertices.
        c: (3,) the centre that was subtracted.
        s: the scale that was divided by (the radius about ``c``).
    """
    used = V[referenced_vertices(len(V), F)]
    if center == "bbox":
        c = 0.5 * (used.min(axis=0) + used.max(axis=0))
    elif center == "mean":
        c = used.mean(axis=0)
    elif center == "area":
        if F is None:
            raise ValueError("center='area' needs the faces F")
        c = surface_centroid(V, F)
    else:
        raise ValueError(f"center must be 'bbox', 'mean' or 'area', got {center!r}")
    r = float(np.linalg.norm(used - c, axis=1).max())
    if not np.isfinite(r) or r <= 0:
        raise MeshError("cannot normalize a mesh whose vertices all coincide (or are not finite)")
    with np.errstate(invalid="ignore", over="ignore"):
        return (V - c) / r, c, r


def save_ply(path: str | os.PathLike, V: np.ndarray, F: np.ndarray, colors: np.ndarray | None = None,
             comments: tuple[str, ...] | list[str] = ()) -> None:
    """Write ``V`` (n,3) float, ``F`` (m,3) int (0-based) and optional per-vertex ``colors`` (n,3) in [0, 1]
    as an ASCII PLY file (vertex order preserved; colours as uchar red/green/blue, which MeshLab and Blender
    show as vertex colours). ``comments``: header comment lines (no newlines)."""
    V, F = np.asarray(V, np.float64), np.asarray(F, np.int64)
    if colors is not None:
        colors = np.asarray(colors, np.float64)
        if colors.shape != V.shape:
            raise ValueError(f"save_ply: colors must be (n_vertices, 3) = {V.shape}, got {colors.shape}")
    head = ["ply", "format ascii 1.0", *(f"comment {c}" for c in comments), f"element vertex {len(V)}",
            "property float x", "property float y", "property float z"]
    if colors is not None:
        head += ["property uchar red", "property uchar green", "property uchar blue"]
    head += [f"element face {len(F)}", "property list uchar int vertex_indices", "end_header"]
    if colors is None:
        rows = [f"{x:.9g} {y:.9g} {z:.9g}" for x, y, z in V]
    else:
        rgb = np.clip(np.round(colors * 255), 0, 255).astype(np.int64)
        rows = [f"{x:.9g} {y:.9g} {z:.9g} {r} {g} {b}" for (x, y, z), (r, g, b) in zip(V, rgb)]
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(head) + "\n")
        fh.write("".join(r + "\n" for r in rows))
        fh.write("".join(f"3 {a} {b} {c}\n" for a, b, c in F))
