"""Reading and writing landmark vertex-id files (``vid,Name`` lines or bare ids; 1-based only when declared)."""
from __future__ import annotations

import os
import warnings

import numpy as np


def _check_unique(path: str, ids: list[int], line_nos: list[int], names: list[str | None]) -> None:
    """Raise ValueError naming the file and both lines when a vertex id, or a landmark name, appears twice."""
    first_line: dict[int, int] = {}
    for vid, line_no in zip(ids, line_nos):
        if vid in first_line:
            raise ValueError(f"{path}:{line_no}: vertex id {vid} is listed twice (first on line "
                             f"{first_line[vid]}); each landmark must be a different vertex: remove or fix one")
        first_line[vid] = line_no
    first_name: dict[str, int] = {}
    for name, line_no in zip(names, line_nos):
        if name is None:
            continue
        if name in first_name:
            raise ValueError(f"{path}:{line_no}: landmark name {name!r} is listed twice (lines {first_name[name]} "
                             f"and {line_no}); each landmark needs its own name: rename or remove one")
        first_name[name] = line_no


ONE_BASED_HEADERS = ("# 1-based", "# one-based")


def _declared_one_based(line: str) -> bool:
    """True for a header comment declaring 1-based ids (``# 1-based`` / ``# one-based``, any case)."""
    return line.lower().replace(" ", "") in {h.replace(" ", "") for h in ONE_BASED_HEADERS}


def read_landmarks(path: str | os.PathLike, n_vertices: int | None = None,
                   one_based: bool | str = False) -> tuple[np.ndarray, list[str]]:
    """Read landmark vertex ids and names.

    Each non-empty line is ``vid,Name`` or a bare integer ``vid`` (then the name is ``str(vid)`` of the
    0-based id); lines starting with ``#`` are comments. The file's last line may lack a newline.

    Ids are 0-based. A file is read as 1-based only when it says so (a comment line ``# 1-based`` before its
    first id) or ``one_based`` does: True, or "auto" = 1-based exactly when every id fits 1..n_vertices, none
    is 0 and one is n_vertices (past the last 0-based id; a ``UserWarning`` says so). Nothing is ever guessed
    otherwise: an id out of range (e.g. a typo n_vertices in a 0-based file) is an error naming the file and
    the line, never a reason to shift the other ids.

    Args:
        path: text file.
        n_vertices: number of vertices of the mesh the ids refer to (enables the range check); None skips it.
        one_based: False (0-based unless the file's header says 1-based), True, or "auto" (see above).
    Returns:
        ids: (k,) int64 0-based vertex ids, in file order.
        names: list of k names.
    Raises:
        ValueError: unparsable line, id out of range (id 0 in a 1-based file), the same vertex id twice (two
        landmarks cannot be one vertex: the truth "landmark i <-> landmark i" would be ambiguous) or the same
        name twice; the message names the file and the (1-based) lines.
    """
    path = os.fspath(path)
    if one_based not in (False, True, "auto"):
        raise ValueError(f"read_landmarks: one_based must be False, True or 'auto', got {one_based!r}")
    ids: list[int] = []
    names: list[str | None] = []
    line_nos: list[int] = []
    header_line = None
    with open(path, "r", encoding="utf-8") as fh:
        for line_no, raw in enumerate(fh, start=1):
            line = raw.strip()
            if not line:
                continue
            if line.startswith("#"):
                if not ids and _declared_one_based(line):
                    header_line = line_no
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
    _check_unique(path, ids, line_nos, names)
    arr = np.asarray(ids, dtype=np.int64)
    if header_line is not None:
        one_based, why = True, f"its line {header_line} says 1-based"
    else:
        why = "one_based=True"
    if one_based == "auto":
        one_based = bool(n_vertices is not None and len(arr) and np.any(arr == n_vertices) and not np.any(arr == 0))
        if one_based:
            warnings.warn(f"{path}: contains id {n_vertices} == number of vertices and no 0: "
                          "treating the file as 1-based and subtracting 1 (one_based='auto')", UserWarning,
                          stacklevel=2)
        why = "one_based='auto'"
    if one_based and len(arr):
        zero = np.flatnonzero(arr == 0)
        if len(zero):
            raise ValueError(f"{path}:{line_nos[int(zero[0])]}: vertex id 0 in a 1-based file ({why}); 1-based ids "
                             "run from 1: fix the id, or remove the '# 1-based' line if the file is 0-based")
        arr = arr - 1
    if n_vertices is not None and len(arr):
        over = np.flatnonzero(arr >= n_vertices)
        if len(over):
            i = int(over[0])
            hint = (f"1-based ids run 1..{n_vertices}" if one_based else
                    f"ids are 0-based, 0..{n_vertices - 1}; if the whole file is 1-based, put a line '# 1-based' "
                    "above its first id")
            raise ValueError(f"{path}:{line_nos[i]}: vertex id {ids[i]} is out of range for a mesh of {n_vertices} "
                             f"vertices ({hint})")
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
