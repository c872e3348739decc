"""Reading and writing landmark vertex-id files (``vid,Name`` lines or bare ids), with 1-based file detection."""
from __future__ import annotations

import os
import warnings

import numpy as np


def _check_unique(path: str, ids: list[int], line_nos: list[int]) -> None:
    """Raise ValueError naming the file and both lines when a vertex id appears twice."""
    first_line: dict[int, int] = {}
    for vid, line_no in zip(ids, line_nos):
        if vid in first_line:
            raise ValueError(f"{path}:{line_no}: vertex id {vid} is listed twice (first on line "
                             f"{first_line[vid]}); each landmark must be a different vertex: remove or fix one")
        first_line[vid] = line_no


def read_landmarks(path: str | os.PathLike, n_vertices: int | None = None) -> tuple[np.ndarray, list[str]]:
    """Read landmark vertex ids and names.

    Each non-empty line is ``vid,Name`` or a bare integer ``vid`` (then the name is ``str(vid)`` of the
    0-based id). The file's last line may lack a newline.

    1-based files: when ``n_vertices`` is given, a file that contains the id ``n_vertices`` (one past the
    last 0-based id) and no id 0 is taken to be 1-based; every id is decremented and a ``UserWarning`` is
    issued. A file with both 0 and ``n_vertices`` is inconsistent and raises.

    Args:
        path: text file.
        n_vertices: number of vertices of the mesh the ids refer to (enables range checks and 1-based
            detection); None skips both except the non-negativity check.
    Returns:
        ids: (k,) int64 0-based vertex ids, in file order.
        names: list of k names.
    Raises:
        ValueError: unparsable line, id out of range, or the same vertex id twice (two landmarks cannot be one
        vertex: the truth "landmark i <-> landmark i" would be ambiguous); the message names the file and the
        (1-based) lines.
    """
    path = os.fspath(path)
    ids: list[int] = []
    names: list[str | None] = []
    line_nos: list[int] = []
    with open(path, "r", encoding="utf-8") as fh:
        for line_no, raw in enumerate(fh, start=1):
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            head, _, name = line.partition(",")
            try:
                vid = int(head.strip())
            except ValueError:
                raise ValueError(f"{path}:{line_no}: expected 'vid,Name' or an integer id, got {line!r}") from None
            if vid < 0:
                raise ValueError(f"{path}:{line_no}: negative vertex id {vid}")
            ids.append(vid)
            names.append(name.strip() or None)
            line_nos.append(line_no)
    _check_unique(path, ids, line_nos)
    arr = np.asarray(ids, dtype=np.int64)
    if n_vertices is not None and len(arr):
        has_n, has_zero = bool(np.any(arr == n_vertices)), bool(np.any(arr == 0))
        if has_n and has_zero:
            bad = line_nos[int(np.flatnonzero(arr == n_vertices)[0])]
            raise ValueError(
                f"{path}:{bad}: id {n_vertices} is out of range 0..{n_vertices - 1}, and the file also holds id 0,"
                " so it is not simply 1-based"
            )
        if has_n:
            warnings.warn(f"{path}: contains id {n_vertices} == number of vertices and no 0: "
                          "treating the file as 1-based and subtracting 1", UserWarning, stacklevel=2)
            arr = arr - 1
        over = np.flatnonzero(arr >= n_vertices)
        if len(over):
            i = int(over[0])
            raise ValueError(f"{path}:{line_nos[i]}: vertex id {ids[i]} is out of range 0..{n_vertices - 1}")
    out_names = [nm if nm is not None else str(int(v)) for nm, v in zip(names, arr)]
    return arr, out_names


def format_landmarks(ids, names) -> str:
    """The text of a landmark file: one ``vid,Name`` line per landmark, in the given order, newline-terminated.

    Args:
        ids: (k,) int 0-based vertex ids.
        names: k names (no comma or newline: ``read_landmarks`` splits on the first comma of a line).
    Returns:
        The file text ("" for k = 0); ``read_landmarks`` reads it back to the same ids and names.
    Raises:
        ValueError: ids and names differ in length, an id is negative, or a name holds a comma or newline.
    """
    ids = [int(v) for v in np.asarray(ids).reshape(-1)]
    names = [str(n) for n in names]
    if len(ids) != len(names):
        raise ValueError(f"format_landmarks: {len(ids)} vertex ids but {len(names)} names; give one name per id")
    for vid, name in zip(ids, names):
        if vid < 0:
            raise ValueError(f"format_landmarks: negative vertex id {vid} (landmark {name!r})")
        if "," in name or "\n" in name or "\r" in name or name != name.strip() or not name:
            raise ValueError(f"format_landmarks: landmark name {name!r} (vertex {vid}) must be non-empty, "
                             "without commas, newlines or surrounding spaces")
    return "".join(f"{vid},{name}\n" for vid, name in zip(ids, names))


def write_landmarks(path: str | os.PathLike, ids, names) -> None:
    """Write ``format_landmarks(ids, names)`` to ``path`` (UTF-8), creating its parent folder if needed."""
    text = format_landmarks(ids, names)
    folder = os.path.dirname(os.fspath(path))
    if folder:
        os.makedirs(folder, exist_ok=True)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)


def subset_positions(ids: np.ndarray, subset_ids: np.ndarray, subset_name: str = "subset",
                     full_name: str = "the landmark list") -> np.ndarray:
    """(k,) int positions of the vertex ids subset_ids (k,) within ids (L,) (e.g. the sparse landmarks within
    all landmarks). Raises ValueError naming ``subset_name`` / ``full_name`` for ids missing from ``ids``."""
    where = {int(v): i for i, v in enumerate(ids)}
    missing = [int(v) for v in subset_ids if int(v) not in where]
    if missing:
        raise ValueError(f"{subset_name}: sparse landmark vertices {missing} are not in {full_name}")
    return np.array([where[int(v)] for v in subset_ids], dtype=np.int64)
