"""Load the course's pre-rendered views (``NNN_V.png``) as square grayscale images.

Course format: one PNG per (item, view), named ``<item>_<view>.png`` (e.g. ``007_12.png``), palette
or RGB, cropped to the object (sizes vary), background pure blue (0, 0, 255). A grayscale view (``L``, ``LA``,
e.g. a course view converted to gray: blue became gray 29) has no blue: its background is the most frequent
border gray (the object touches the border of a cropped view only at a few pixels). Loading maps the
background to white, converts to grayscale (ITU-R 601 luma, [0, 1]), pads to a square (object
centred, white padding) and resizes to ``size`` x ``size`` with an anti-aliasing filter, giving images
that match ``corr_core.alignment.render.render_views`` (dark object on white).
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from PIL import Image

BACKGROUND_RGB = (0, 0, 255)
GRAY_MODES = ("1", "L", "LA", "La", "I", "I;16", "F")  # PIL modes without colour
_VIEW_NAME = re.compile(r"^(?P<item>.+)_(?P<view>\d+)\.png$", re.IGNORECASE)


def to_gray_white_background(rgb: np.ndarray, background=BACKGROUND_RGB) -> np.ndarray:
    """Grayscale in [0, 1] with every pixel equal to ``background`` set to 1.0.

    Args:
        rgb: (H, W, 3) uint8 image.
        background: the exact RGB triple of the background.
    Returns:
        (H, W) float32.
    """
    rgb = np.asarray(rgb)
    gray = (rgb[..., :3].astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)) / 255.0
    is_background = np.all(rgb[..., :3] == np.asarray(background, dtype=rgb.dtype), axis=-1)
    gray[is_background] = 1.0
    return np.clip(gray, 0.0, 1.0)


def background_color(rgb: np.ndarray, mode: str = "RGB") -> tuple[int, int, int]:
    """The background colour of a view: pure blue (0, 0, 255) for a colour view (palette, RGB, RGBA), the most
    frequent colour of the image border for a grayscale one (ties: the smallest).

    Args:
        rgb: (H, W, 3) uint8 image (after conversion to RGB); mode: the PIL mode of the file ("L", "P", ...).
    Returns:
        the RGB triple to treat as background.
    """
    if mode not in GRAY_MODES:
        return BACKGROUND_RGB
    rgb = np.asarray(rgb)[..., :3]
    border = np.concatenate([rgb[0], rgb[-1], rgb[:, 0], rgb[:, -1]])
    colors, counts = np.unique(border, axis=0, return_counts=True)
    return tuple(int(c) for c in colors[int(np.argmax(counts))])


def pad_to_square(image: np.ndarray, *, fill: float = 1.0) -> np.ndarray:
    """Pad a (H, W) image with ``fill`` to (S, S), S = max(H, W), keeping it centred."""
    height, width = image.shape
    side = max(height, width)
    top, left = (side - height) // 2, (side - width) // 2
    out = np.full((side, side), fill, dtype=np.float32)
    out[top : top + height, left : left + width] = image
    return out


def resize_square(image: np.ndarray, size: int) -> np.ndarray:
    """Resize a (S, S) float image to (size, size) with PIL's anti-aliased bilinear filter."""
    resized = Image.fromarray(np.asarray(image, dtype=np.float32)).resize(
        (size, size), Image.Resampling.BILINEAR
    )
    return np.clip(np.asarray(resized, dtype=np.float32), 0.0, 1.0)


def crop_to_object(image: np.ndarray, size: int | None = None, *, background: float = 1.0) -> np.ndarray:
    """Crop a rendered view to its object's bounding box, pad square, resize: the course framing.

    Args:
        image: (H, W) float image with a uniform ``background`` (e.g. from ``render_views``).
        size: output side; None keeps the input height.
        background: background value; pixels != background count as object.
    Returns:
        (size, size) float32; an all-background image is returned resized, uncropped.
    """
    image = np.asarray(image, dtype=np.float32)
    size = image.shape[0] if size is None else size
    rows = np.flatnonzero((image != background).any(axis=1))
    cols = np.flatnonzero((image != background).any(axis=0))
    if rows.size:
        image = image[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
    return resize_square(pad_to_square(image, fill=background), size)


def load_view_image(path: str | os.PathLike, *, size: int = 120) -> np.ndarray:
    """Load one course view as a (size, size) float32 grayscale image, white background.

    Args:
        path: PNG path (palette or RGB with background (0, 0, 255); grayscale or other colour views: the
            background is the most frequent border colour, see ``background_color``).
        size: output side in pixels.
    Returns:
        (size, size) float32 in [0, 1].
    Raises:
        FileNotFoundError / ValueError naming the file when it is missing or not a readable image.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"view image not found: {path}")
    try:
        with Image.open(path) as handle:
            mode = handle.mode
            rgb = np.asarray(handle.convert("RGB"))
    except Exception as error:  # PIL raises several types (UnidentifiedImageError, OSError, ...)
        raise ValueError(f"cannot read view image {path}: {error}") from error
    gray = to_gray_white_background(rgb, background_color(rgb, mode))
    return resize_square(pad_to_square(gray), size)


def load_view_stack(paths: list[str | os.PathLike], *, size: int = 120) -> np.ndarray:
    """Load views in the given order.

    Args:
        paths: V image paths (e.g. one item's views sorted by view index).
        size: output side in pixels.
    Returns:
        (V, size, size) float32.
    """
    if len(paths) == 0:
        raise ValueError("load_view_stack needs at least one path")
    return np.stack([load_view_image(path, size=size) for path in paths])


def find_view_files(folder: str | os.PathLike, n_views: int | None = None) -> dict[str, list[str]]:
    """Index a folder of ``<item>_<view>.png`` files.

    Args:
        folder: directory to scan (not recursive).
        n_views: views every item must have (indices 0..n_views-1); None = the largest index found
            in the folder plus one.
    Returns:
        {item: [path of view 0, path of view 1, ...]} with items sorted, paths sorted by view index.
    Raises:
        FileNotFoundError if the folder is missing; ValueError if it holds no view files, or naming
        every item with missing (or out-of-range) view indices.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"view folder not found: {folder}")
    views: dict[str, dict[int, str]] = {}
    for entry in folder.iterdir():
        match = _VIEW_NAME.match(entry.name)
        if match and entry.is_file():
            views.setdefault(match["item"], {})[int(match["view"])] = str(entry)
    if not views:
        raise ValueError(f"no <item>_<view>.png files in {folder}")
    if n_views is None:
        n_views = 1 + max(max(item_views) for item_views in views.values())

    problems = []
    for item in sorted(views):
        missing = sorted(set(range(n_views)) - set(views[item]))
        extra = sorted(set(views[item]) - set(range(n_views)))
        if missing:
            problems.append(f"item {item} is missing views {missing}")
        if extra:
            problems.append(f"item {item} has views {extra} outside 0..{n_views - 1}")
    if problems:
        raise ValueError(
            f"incomplete views in {folder} (expected {n_views} per item): " + "; ".join(problems)
        )
    return {item: [views[item][k] for k in range(n_views)] for item in sorted(views)}
