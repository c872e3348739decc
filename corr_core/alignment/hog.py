"""Histogram-of-oriented-gradients features for rendered views.

``hog_dollar`` reimplements Piotr Dollár's toolbox ``hog(I, binSize=8, nOrients=9, clip=0.2)``
(channels/hog.m -> gradientMag + gradientHist(softBin=1, useHog=1), gradientMex.cpp) in vectorized
numpy:

1. gradients: centred differences ``(I[i+1]-I[i-1])/2`` inside, one-sided differences at the border
   (``np.gradient``); magnitude M, unsigned orientation O = atan2(gy, gx) mod pi in [0, pi).
2. soft binning: orientation bin k is centred at k*pi/nOrients, linear (circular) interpolation between
   the two nearest bins; spatial cell c is centred at pixel (c+0.5)*bin-0.5, bilinear interpolation
   between the two nearest cells per axis, weights falling outside the grid dropped. Magnitudes are
   divided by bin**2. Pixels beyond the last full cell (H % bin rows, W % bin cols) are ignored.
   Border cells are multiplied by 8/7 (corners by (8/7)**2), as the toolbox does, to make up for the
   weight they lose.
3. normalization: for every 2x2 block of cells the L2 norm over all its 4*nOrients values; each cell's
   histogram is divided by the norms of the 4 blocks containing it (blocks clamped at the grid border,
   i.e. the block-norm grid is edge-padded), giving 4*nOrients values; each value clipped at ``clip``;
   no renormalization. Channel order = (normalization c, orientation o) -> c*nOrients + o with
   c = 0: block starting at this cell, 1: the block one cell up, 2: one cell left, 3: up-left; this is
   the toolbox's output order H(y, x, :).

Orientations reproduce the toolbox's acos lookup table (cosine truncated to multiples of 1e-4).
Known difference to the compiled toolbox: it computes magnitudes and cosines with SSE approximate
reciprocal square roots (~4e-4 relative error, CPU dependent); this code uses exact float32 math.
Checked against the compiled gradientMex.cpp: smooth images agree within ~3e-3 (values <= 0.2);
on images with exactly vertical edges the toolbox's approximate cosine can fall a few 1e-4 below 1,
which the acos table turns into up to 0.028 rad, moving a few percent of the weight from
orientation bin 0 to bin 1 (feature differences up to ~0.035 on the course chair views); this code
keeps such edges in bin 0. Colour images are not supported (grayscale only).
"""
from __future__ import annotations

import numpy as np

_BORDER_GAIN = 8.0 / 7.0  # hard-coded in gradientMex.cpp gradHist(), independent of bin size
_DOLLAR_CHUNK = 16  # views per vectorized pass in hog_features: a shape's 16 views at once (4..16 measured alike)


def _gradients(images: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(gx, gy, M): (..., H, W) float32 centred-difference gradients (one-sided at the border) and magnitude."""
    gy, gx = np.gradient(images, axis=(-2, -1))
    return gx, gy, np.hypot(gx, gy)


def _orientation(gx: np.ndarray, gy: np.ndarray, magnitude: np.ndarray) -> np.ndarray:
    """Unsigned orientation in [0, pi) of gradients (gx, gy) of magnitude M (float32, any shape, elementwise).

    O = acos(gx / M * sign(gy)) = atan2(gy, gx) mod pi, with the cosine truncated to a multiple of
    1e-4 as the toolbox's acos lookup table does (this matters near 0 where acos is steep: up to
    0.014 rad) and pi replaced by pi - 1e-6. Flat pixels (M = 0) get pi / 2 (they carry no weight).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        cosine = np.where(magnitude > 0, gx / magnitude, np.float32(0.0))
    cosine = np.where(np.signbit(gy), -cosine, cosine)
    table_index = np.clip(np.trunc(cosine * np.float32(10000.0)), -10000, 10000)
    orientation = np.arccos(table_index / np.float32(10000.0)).astype(np.float32)
    np.minimum(orientation, np.float32(np.pi - 1e-6), out=orientation)
    return orientation


def _interpolate_cells(values: np.ndarray, bin_size: int, axis: int) -> np.ndarray:
    """Linearly interpolate per-pixel values into cells along one axis.

    Cell c is centred at pixel (c + 0.5) * bin_size - 0.5; pixel i gives weight 1 - f to cell
    floor(p) and f to floor(p) + 1, p = (i + 0.5) / bin_size - 0.5, f = p - floor(p); weights
    outside [0, n_cells) are dropped. Pixels sharing floor(p) form runs of bin_size pixels starting at
    pixel bin_size // 2 + k * bin_size, and f depends only on the position inside the run, so padding
    to align the runs turns the sum into a reshape (no BLAS, no scatter).

    Args:
        values: array whose ``axis`` has length n_cells * bin_size.
    Returns:
        the same array with that axis replaced by n_cells.
    """
    values = np.moveaxis(values, axis, 0)
    n_cells = values.shape[0] // bin_size
    shift = bin_size // 2  # first pixel with floor(p) == 0
    padding = [(bin_size - shift, shift)] + [(0, 0)] * (values.ndim - 1)  # run k <-> floor(p) = k - 1
    runs = np.pad(values, padding).reshape((n_cells + 1, bin_size) + values.shape[1:])
    frac = ((shift + np.arange(bin_size) + 0.5) / bin_size - 0.5).astype(values.dtype)
    upper_part = np.einsum("r,kr...->k...", frac, runs)
    lower_part = runs.sum(axis=1) - upper_part  # run k -> cell k - 1; upper_part: run k -> cell k
    cells = upper_part[:-1] + lower_part[1:]
    return np.moveaxis(cells, 0, axis)


def _binned_rows(gx: np.ndarray, gy: np.ndarray, magnitude: np.ndarray, bin_size: int, n_orients: int
                 ) -> np.ndarray:
    """Orientation binning, then interpolation into cell rows: ``_interpolate_cells(per_pixel, bin_size, -3)``.

    per_pixel (..., R, C, O) holds each pixel's magnitude m = M / bin**2 split between its two nearest
    orientation bins (bin floor(p) gets (1 - f) * m, the next bin, circularly, f * m; p = orientation * O / pi,
    f = p - floor(p)). Most of a rendered view is flat (zero gradient), so this builds per_pixel (and the
    orientations) only for the runs of bin_size rows (the reshape of ``_interpolate_cells``) that hold a pixel
    with a gradient, column by column: a run without one gives exact zeros. Every value is computed by the same
    elementwise float32 operations, and the sums over a run in the same order (sequential over its rows) as the
    einsum and sum of ``_interpolate_cells``, so the result is bit-identical to it.

    Args:
        gx, gy, magnitude: (..., R, C) float32 gradients and their magnitude M, R = n_rows * bin_size.
    Returns:
        (..., n_rows, C, n_orients) float32.
    """
    lead, (height, width) = magnitude.shape[:-2], magnitude.shape[-2:]
    n_images, n_runs = int(np.prod(lead, dtype=np.int64)), height // bin_size + 1
    shift = bin_size // 2  # first pixel row with floor(p) == 0; run k <-> cell rows k - 1 and k
    padding = [(0, 0), (bin_size - shift, shift), (0, 0)]
    # (images, runs * bin, C): zero rows before and after, as _interpolate_cells pads
    gx, gy, magnitude = (np.pad(g.reshape(n_images, height, width), padding) for g in (gx, gy, magnitude))
    image, run, column = np.nonzero((magnitude != 0).reshape(n_images, n_runs, bin_size, width).any(axis=2))
    # (n, bin) flat pixel indices of the active (image, run, column) groups, run rows in order
    pixels = ((image * n_runs + run) * bin_size)[:, None] + np.arange(bin_size)
    pixels = pixels * width + column[:, None]
    M = magnitude.ravel()[pixels]
    o = _orientation(gx.ravel()[pixels], gy.ravel()[pixels], M)
    m = M / np.float32(bin_size**2)

    bin_position = o * np.float32(n_orients / np.pi)
    bin_lower = np.floor(bin_position)
    upper_weight = (bin_position - bin_lower) * m
    lower_weight = m - upper_weight
    bin_lower = bin_lower.astype(np.intp).ravel() % n_orients
    bin_upper = (bin_lower + 1) % n_orients
    per_pixel = np.zeros(m.size * n_orients, np.float32)  # (n, bin, O) through flat indices pixel * O + bin
    first = np.arange(0, per_pixel.size, n_orients)
    per_pixel[first + bin_lower] = lower_weight.ravel()
    per_pixel[first + bin_upper] += upper_weight.ravel()  # += keeps n_orients == 1 correct
    per_pixel = per_pixel.reshape(len(image), bin_size, n_orients)

    frac = ((shift + np.arange(bin_size) + 0.5) / bin_size - 0.5).astype(np.float32)
    upper_part, total = frac[0] * per_pixel[:, 0], per_pixel[:, 0]
    for r in range(1, bin_size):
        upper_part = upper_part + frac[r] * per_pixel[:, r]
        total = total + per_pixel[:, r]
    upper = np.zeros((n_runs, n_images, width, n_orients), np.float32)
    lower = np.zeros_like(upper)
    upper[run, image, column] = upper_part  # run k -> cell row k
    lower[run, image, column] = total - upper_part  # run k -> cell row k - 1
    cells = upper[:-1] + lower[1:]
    # the memory layout of _interpolate_cells' result (rows first), which the column pass's pad and einsum follow
    return np.moveaxis(cells.reshape(cells.shape[:1] + lead + cells.shape[2:]), 0, -3)


def gradient_histograms(images: np.ndarray, *, bin_size: int = 8, n_orients: int = 9) -> np.ndarray:
    """Soft-binned, unnormalized orientation histograms (toolbox gradientHist, softBin=1).

    Args:
        images: (..., H, W) grayscale image(s) (any real dtype; [0, 1] expected).
        bin_size: cell size in pixels.
        n_orients: number of unsigned orientation bins over [0, pi).
    Returns:
        R: (..., H // bin_size, W // bin_size, n_orients) float32, including the 8/7 border gain.
    """
    images = np.asarray(images, dtype=np.float32)
    if images.ndim < 2:
        raise ValueError(f"images must be (..., H, W) grayscale, got shape {images.shape}")
    height, width = images.shape[-2:]
    n_rows, n_cols = height // bin_size, width // bin_size
    if n_rows < 2 or n_cols < 2:
        raise ValueError(f"image {images.shape} too small: need at least 2x2 cells of {bin_size} px")
    gx, gy, magnitude = (g[..., : n_rows * bin_size, : n_cols * bin_size] for g in _gradients(images))
    hist = _interpolate_cells(_binned_rows(gx, gy, magnitude, bin_size, n_orients), bin_size, -2)
    hist[..., 0, :, :] *= _BORDER_GAIN
    hist[..., :, 0, :] *= _BORDER_GAIN
    hist[..., :, -1, :] *= _BORDER_GAIN
    hist[..., -1, :, :] *= _BORDER_GAIN
    return np.ascontiguousarray(hist, dtype=np.float32)


def normalize_cells(hist: np.ndarray, *, bin_size: int = 8, clip: float = 0.2) -> np.ndarray:
    """Four 2x2-block normalizations per cell, clipped (toolbox hogNormMatrix + hogChannels type 0).

    Args:
        hist: (..., h, w, O) unnormalized cell histograms, h, w >= 2.
        bin_size: only sets the tiny epsilon 1e-4 / 4 / bin**4 the toolbox adds under the root.
        clip: upper bound of every output value.
    Returns:
        (..., h, w, 4 * O) float32, channel c * O + o.
    """
    energy = np.einsum("...o,...o->...", hist, hist)  # (..., h, w)
    block_energy = (
        energy[..., :-1, :-1] + energy[..., 1:, :-1] + energy[..., :-1, 1:] + energy[..., 1:, 1:]
    )
    eps = np.float32(1e-4 / 4 / bin_size**4)
    pad = [(0, 0)] * (energy.ndim - 2) + [(1, 1), (1, 1)]
    inv_norm = np.pad(1.0 / np.sqrt(block_energy + eps), pad, mode="edge").astype(np.float32)
    factors = np.stack(
        [inv_norm[..., 1:, 1:], inv_norm[..., :-1, 1:], inv_norm[..., 1:, :-1], inv_norm[..., :-1, :-1]],
        axis=-1,
    )  # (..., h, w, 4): block at / above / left of / above-left of the cell
    out = factors[..., :, None] * hist[..., None, :]
    np.minimum(out, np.float32(clip), out=out)
    return out.reshape(hist.shape[:-1] + (-1,))


def hog_dollar(image: np.ndarray, *, bin_size: int = 8, n_orients: int = 9, clip: float = 0.2) -> np.ndarray:
    """HOG as Dollár's toolbox ``hog(I, binSize, nOrients, clip)`` (see module docstring).

    Args:
        image: (H, W) grayscale image, values in [0, 1] (the features are nearly scale invariant);
            a stack (..., H, W) is processed in one vectorized pass.
        bin_size: cell size in pixels.
        n_orients: unsigned orientation bins.
        clip: clipping value after normalization.
    Returns:
        (..., H // bin_size, W // bin_size, 4 * n_orients) float32; 120x120 -> (15, 15, 36) = 8100.
    """
    hist = gradient_histograms(image, bin_size=bin_size, n_orients=n_orients)
    return normalize_cells(hist, bin_size=bin_size, clip=clip)


def hog_skimage(image: np.ndarray, **kwargs) -> np.ndarray:
    """skimage.feature.hog with skimage defaults (9 orientations, 8x8 cells, 3x3 blocks, L2-Hys).

    Args:
        image: (H, W) grayscale image.
        **kwargs: passed to ``skimage.feature.hog`` (``feature_vector`` is forced True).
    Returns:
        (D,) float32 feature vector; D = 13689 for 120x120 with defaults.
    """
    from skimage.feature import hog

    kwargs["feature_vector"] = True
    return hog(np.asarray(image, dtype=np.float64), **kwargs).astype(np.float32)


def hog_features(views: np.ndarray, method: str = "dollar", **kwargs) -> np.ndarray:
    """HOG feature vector of every view.

    Args:
        views: (V, H, W) grayscale views.
        method: "dollar" (``hog_dollar``, 8100 values at 120x120) or "skimage" (``hog_skimage``).
        **kwargs: passed to the chosen function.
    Returns:
        (V, D) float32, one flattened feature vector per view.
    """
    views = np.asarray(views)
    if views.ndim != 3 or len(views) == 0:
        raise ValueError(f"views must be a non-empty (V, H, W) stack, got shape {views.shape}")
    if method == "dollar":
        # one vectorized pass over a shape's views (larger stacks in blocks, to bound the memory)
        chunks = [views[i : i + _DOLLAR_CHUNK] for i in range(0, len(views), _DOLLAR_CHUNK)]
        return np.concatenate([hog_dollar(chunk, **kwargs).reshape(len(chunk), -1) for chunk in chunks])
    if method == "skimage":
        return np.stack([hog_skimage(view, **kwargs) for view in views]).astype(np.float32)
    raise ValueError(f"method must be 'dollar' or 'skimage', got {method!r}")


def draw_hog(hog_cells: np.ndarray, *, cell_px: int = 16) -> np.ndarray:
    """Glyph picture of HOG cells: one bar per orientation, brightness = that orientation's energy.

    Bars are drawn perpendicular to the gradient direction (i.e. along the edge), like the toolbox's
    hogDraw. For (h, w, 4*O) Dollár features the 4 normalizations are summed first.

    Args:
        hog_cells: (h, w, C) cell features; C = O or 4*O (orientation-minor channel order c*O + o).
        cell_px: glyph size in pixels.
    Returns:
        (h * cell_px, w * cell_px) float32 in [0, 1], black background, white bars.
    """
    hog_cells = np.asarray(hog_cells, dtype=np.float32)
    n_rows, n_cols, n_channels = hog_cells.shape
    n_orients = n_channels // 4 if n_channels % 4 == 0 and n_channels >= 8 else n_channels
    energy = hog_cells.reshape(n_rows, n_cols, -1, n_orients).sum(axis=2)  # (h, w, O)
    peak = energy.max()
    if peak > 0:
        energy = energy / peak

    centre = (cell_px - 1) / 2.0
    ys, xs = np.mgrid[0:cell_px, 0:cell_px].astype(np.float32) - centre
    angles = np.arange(n_orients) * np.pi / n_orients + np.pi / 2  # edge direction
    # distance of each glyph pixel to the bar through the centre along each edge direction
    along = xs[None] * np.cos(angles)[:, None, None] + ys[None] * np.sin(angles)[:, None, None]
    across = -xs[None] * np.sin(angles)[:, None, None] + ys[None] * np.cos(angles)[:, None, None]
    bars = ((np.abs(across) <= 0.6) & (np.abs(along) <= centre + 0.5)).astype(np.float32)  # (O, p, p)

    glyphs = np.einsum("rco,oyx->rcyx", energy, bars)
    glyphs = np.minimum(glyphs, 1.0)
    return glyphs.transpose(0, 2, 1, 3).reshape(n_rows * cell_px, n_cols * cell_px).astype(np.float32)
