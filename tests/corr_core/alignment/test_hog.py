import math

import numpy as np
import pytest

from corr_core.alignment.hog import draw_hog, gradient_histograms, hog_dollar, hog_features, hog_skimage
from corr_core.alignment.render import render_views
from corr_core.generate.chairs import canonical_chair
from corr_core.geometry.mesh_io import normalize_mesh

N_ORIENTS = 9


def smooth_test_image(height=35, width=42):
    """Analytic image with contrast growing to the right and down (so block norms differ)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    amp = 0.02 + 0.3 * (x / 41) ** 2 * (0.2 + y / 34)
    return (0.5 + amp * np.sin(0.35 * x + 0.1 * y) + 0.1 * np.cos(0.2 * y - 0.006 * x * x)).astype(np.float32)


def slow_reference_hog(image, bin_size=8, n_orients=9, clip=0.2):
    """Per-pixel transcription of the toolbox's gradMag / gradHist(softBin=1) / hog steps."""
    image = np.asarray(image, dtype=np.float32)
    h, w = image.shape
    hb, wb = h // bin_size, w // bin_size
    hist = np.zeros((hb, wb, n_orients))
    for y in range(hb * bin_size):
        for x in range(wb * bin_size):
            x0, x1, rx = max(x - 1, 0), min(x + 1, w - 1), (0.5 if 0 < x < w - 1 else 1.0)
            y0, y1, ry = max(y - 1, 0), min(y + 1, h - 1), (0.5 if 0 < y < h - 1 else 1.0)
            # float32 like the toolbox, so the 1e-4 acos-table truncation lands on the same entry
            gx = np.float32((image[y, x1] - image[y, x0]) * rx)
            gy = np.float32((image[y1, x] - image[y0, x]) * ry)
            magnitude = np.hypot(gx, gy)
            if magnitude == 0:
                continue
            mag = float(magnitude) / bin_size**2
            cosine = gx / magnitude * np.float32(-1 if gy < 0 else 1)
            angle = min(math.acos(int(cosine * np.float32(10000)) / 10000), math.pi - 1e-6)
            o = angle * n_orients / math.pi
            o_lo = int(o)
            o_frac = o - o_lo
            for ob, ow in ((o_lo % n_orients, 1 - o_frac), ((o_lo + 1) % n_orients, o_frac)):
                py = (y + 0.5) / bin_size - 0.5
                px = (x + 0.5) / bin_size - 0.5
                cy, cx = math.floor(py), math.floor(px)
                for ny, wy in ((cy, 1 - (py - cy)), (cy + 1, py - cy)):
                    for nx, wx in ((cx, 1 - (px - cx)), (cx + 1, px - cx)):
                        if 0 <= ny < hb and 0 <= nx < wb:
                            hist[ny, nx, ob] += mag * ow * wy * wx
    for cy in range(hb):
        for cx in range(wb):
            gain = (8 / 7) ** ((cy == 0) + (cy == hb - 1) + (cx == 0) + (cx == wb - 1))
            hist[cy, cx] *= gain
    energy = (hist**2).sum(axis=2)
    eps = 1e-4 / 4 / bin_size**4
    out = np.zeros((hb, wb, 4 * n_orients))
    for cy in range(hb):
        for cx in range(wb):
            # normalization c: block starting at (cy - dy, cx - dx), clamped into the block grid
            for c, (dy, dx) in enumerate(((0, 0), (1, 0), (0, 1), (1, 1))):
                by = min(max(cy - dy, 0), hb - 2)
                bx = min(max(cx - dx, 0), wb - 2)
                block = energy[by, bx] + energy[by + 1, bx] + energy[by, bx + 1] + energy[by + 1, bx + 1]
                for o in range(n_orients):
                    out[cy, cx, c * n_orients + o] = min(hist[cy, cx, o] / math.sqrt(block + eps), clip)
    return out


def test_output_shapes():
    rng = np.random.default_rng(0)
    assert hog_dollar(rng.random((120, 120))).shape == (15, 15, 36)
    assert hog_dollar(rng.random((37, 53))).shape == (4, 6, 36)
    assert hog_dollar(rng.random((40, 48)), bin_size=4, n_orients=6).shape == (10, 12, 24)
    assert hog_features(rng.random((3, 120, 120))).shape == (3, 8100)
    assert hog_features(rng.random((2, 120, 120)), method="skimage").shape == (2, 13689)
    assert hog_skimage(rng.random((120, 120))).shape == (13689,)
    assert hog_features(rng.random((2, 64, 64))).dtype == np.float32
    with pytest.raises(ValueError):
        hog_dollar(rng.random((12, 40)))  # fewer than 2 cell rows
    with pytest.raises(ValueError):
        hog_features(rng.random((2, 64, 64)), method="nope")


def test_stack_equals_per_image():
    rng = np.random.default_rng(1)
    views = rng.random((4, 48, 56)).astype(np.float32)
    stacked = hog_features(views)
    single = np.stack([hog_dollar(v).ravel() for v in views])
    np.testing.assert_allclose(stacked, single, atol=1e-6)


def chair_views(index=2, n_views=16, size=120):
    """A generated chair's views as the align.views stage stores them (uint8) and align.hog reads them."""
    V, F = canonical_chair(0, index)
    views = render_views(normalize_mesh(V, "area", F)[0], F, n_views=n_views, image_size=size)
    return np.clip(np.rint(views * 255.0), 0, 255).astype(np.uint8).astype(np.float32) / 255.0


def dense_reference_histograms(images, bin_size=8, n_orients=9):
    """gradient_histograms as first written: the (..., H, W, O) per-pixel histograms of every pixel, then the
    run-reshape interpolation over rows and columns (einsum + sum over each run of bin_size pixels)."""
    images = np.asarray(images, dtype=np.float32)
    rows, cols = images.shape[-2] // bin_size, images.shape[-1] // bin_size
    gy, gx = np.gradient(images, axis=(-2, -1))
    magnitude = np.hypot(gx, gy)
    with np.errstate(divide="ignore", invalid="ignore"):
        cosine = np.where(magnitude > 0, gx / magnitude, np.float32(0.0))
    cosine = np.where(np.signbit(gy), -cosine, cosine)
    table_index = np.clip(np.trunc(cosine * np.float32(10000.0)), -10000, 10000)
    orientation = np.minimum(np.arccos(table_index / np.float32(10000.0)).astype(np.float32),
                             np.float32(np.pi - 1e-6))
    magnitude = magnitude[..., : rows * bin_size, : cols * bin_size] / np.float32(bin_size**2)
    orientation = orientation[..., : rows * bin_size, : cols * bin_size]
    position = orientation * np.float32(n_orients / np.pi)
    lower_bin = np.floor(position)
    upper_weight = (position - lower_bin) * magnitude
    lower_weight = magnitude - upper_weight
    lower_bin = lower_bin.astype(np.intp).ravel() % n_orients
    per_pixel = np.zeros((magnitude.size, n_orients), np.float32)
    pixel = np.arange(magnitude.size)
    per_pixel[pixel, lower_bin] = lower_weight.ravel()
    per_pixel[pixel, (lower_bin + 1) % n_orients] += upper_weight.ravel()
    per_pixel = per_pixel.reshape(magnitude.shape + (n_orients,))

    def interpolate(values, axis):
        values = np.moveaxis(values, axis, 0)
        n_cells, shift = values.shape[0] // bin_size, bin_size // 2
        padding = [(bin_size - shift, shift)] + [(0, 0)] * (values.ndim - 1)
        runs = np.pad(values, padding).reshape((n_cells + 1, bin_size) + values.shape[1:])
        frac = ((shift + np.arange(bin_size) + 0.5) / bin_size - 0.5).astype(values.dtype)
        upper = np.einsum("r,kr...->k...", frac, runs)
        return np.moveaxis(upper[:-1] + (runs.sum(axis=1) - upper)[1:], 0, axis)

    hist = interpolate(interpolate(per_pixel, -3), -2)
    for index in ((..., 0, slice(None), slice(None)), (..., slice(None), 0, slice(None)),
                  (..., slice(None), -1, slice(None)), (..., -1, slice(None), slice(None))):
        hist[index] *= 8.0 / 7.0
    return hist


@pytest.mark.parametrize("bin_size, n_orients", [(8, 9), (4, 6), (5, 9), (8, 1)])
def test_histograms_of_the_gradient_pixels_only_equal_the_dense_computation_bit_for_bit(bin_size, n_orients):
    rng = np.random.default_rng(bin_size * 10 + n_orients)
    flat = np.full((40, 48), 0.5, np.float32)
    edge = flat.copy()
    edge[:, 23:] = 0.2
    cases = {"chair views": chair_views(index=4, n_views=4), "random": rng.random((3, 37, 53)).astype(np.float32),
             "smooth": smooth_test_image(), "flat": flat, "one edge": edge}
    for name, images in cases.items():
        got = gradient_histograms(images, bin_size=bin_size, n_orients=n_orients)
        expected = dense_reference_histograms(images, bin_size, n_orients)
        assert got.dtype == np.float32 and got.shape == expected.shape, name
        np.testing.assert_array_equal(got, expected, err_msg=name)


def test_all_views_in_one_pass_equal_each_view_alone_exactly():
    views = chair_views()
    features = hog_features(views)
    assert features.shape == (16, 8100) and features.dtype == np.float32
    np.testing.assert_array_equal(features, np.stack([hog_dollar(view).ravel() for view in views]))
    np.testing.assert_array_equal(features, hog_features(np.concatenate([views, views]))[16:])  # blocks of 16


def orientation_energy(features):
    return features.reshape(features.shape[0], features.shape[1], 4, N_ORIENTS).sum(axis=(0, 1, 2))


def test_vertical_edge_goes_to_orientation_bin_0():
    image = np.ones((64, 64), np.float32)
    image[:, 29:] = 0.2  # intensity changes along x only: gradient angle 0
    energy = orientation_energy(hog_dollar(image))
    assert energy[0] > 0
    # the toolbox maps angle pi to pi - 1e-6, leaving a ~1e-5 sliver in the last bin
    np.testing.assert_allclose(energy[1:], 0.0, atol=1e-3 * energy[0])


def test_horizontal_edge_splits_between_bins_4_and_5():
    image = np.ones((64, 64), np.float32)
    image[29:, :] = 0.2  # gradient angle pi/2 = bin position 4.5
    energy = orientation_energy(hog_dollar(image))
    np.testing.assert_allclose(energy[4], energy[5], rtol=1e-3)
    others = np.delete(energy, [4, 5])
    assert others.max() < 1e-6 * energy[4]


def test_diagonal_edge_bin():
    # 45 degree gradient (intensity rises along +x and +y): bin position 45/20 = 2.25
    y, x = np.mgrid[0:64, 0:64]
    image = (x + y > 64).astype(np.float32)
    energy = orientation_energy(hog_dollar(image))
    assert np.argmax(energy) == 2


def test_contrast_and_offset_invariance():
    image = smooth_test_image()
    base = hog_dollar(image)
    np.testing.assert_allclose(hog_dollar(0.3 * image + 0.4), base, atol=1e-4)
    np.testing.assert_allclose(hog_dollar(2.0 * image), base, atol=1e-4)


def test_clipping_bound():
    rng = np.random.default_rng(2)
    image = rng.random((64, 80)).astype(np.float32)
    image[20:40, 30:50] = 0.0  # strong isolated edges make some ratios exceed the clip
    features = hog_dollar(image)
    assert features.max() <= 0.2 + 1e-7
    assert np.isclose(features.max(), 0.2)
    assert features.min() >= 0.0
    assert hog_dollar(image, clip=0.1).max() <= 0.1 + 1e-7


@pytest.mark.parametrize("shape", [(24, 40), (21, 35), (35, 42)])
def test_matches_slow_reference(shape):
    rng = np.random.default_rng(sum(shape))
    image = smooth_test_image(*shape) + 0.05 * rng.random(shape).astype(np.float32)
    np.testing.assert_allclose(hog_dollar(image), slow_reference_hog(image), atol=2e-5)


def test_matches_slow_reference_other_parameters():
    image = smooth_test_image(30, 36)
    np.testing.assert_allclose(
        hog_dollar(image, bin_size=5, n_orients=6, clip=0.3),
        slow_reference_hog(image, bin_size=5, n_orients=6, clip=0.3),
        atol=2e-5,
    )


# Output of the compiled toolbox (gradientMex.cpp, hog(I, 8, 9, 0.2)) on smooth_test_image(): the
# toolbox uses SSE approximate reciprocal square roots, so agreement is ~1e-3, not exact.
TOOLBOX_CHANNEL_SUMS = [
    2.1615, 1.1047, 0.7460, 0.7809, 1.5052, 1.8077, 1.8380, 1.8153, 2.4727,
    2.2098, 1.1506, 0.7982, 0.8400, 1.5396, 1.8200, 1.8453, 1.8240, 2.5204,
    2.3816, 1.3904, 0.9326, 1.0024, 1.7647, 2.1236, 2.0971, 2.2126, 2.7578,
    2.4243, 1.4230, 0.9726, 1.0408, 1.7969, 2.1290, 2.1072, 2.2144, 2.7869,
]  # fmt: skip
TOOLBOX_CELL_SUMS = [
    [2.5028, 3.0173, 3.2964, 3.1475, 3.4086],
    [2.2114, 3.7158, 3.0222, 2.5236, 2.6140],
    [2.4901, 3.5236, 3.9648, 3.3904, 3.4966],
    [2.3951, 3.3583, 4.0964, 3.1872, 2.9755],
]
TOOLBOX_CELL_2_3 = [
    0.1025, 0.0793, 0.0714, 0.1087, 0.0786, 0.0329, 0.0279, 0.0353, 0.0732,
    0.1260, 0.0975, 0.0878, 0.1336, 0.0966, 0.0405, 0.0342, 0.0434, 0.0900,
    0.1635, 0.1265, 0.1139, 0.1734, 0.1254, 0.0526, 0.0444, 0.0563, 0.1168,
    0.1779, 0.1376, 0.1239, 0.1885, 0.1363, 0.0572, 0.0483, 0.0612, 0.1270,
]  # fmt: skip


def test_agrees_with_compiled_toolbox_output():
    features = hog_dollar(smooth_test_image())
    assert features.shape == (4, 5, 36)
    np.testing.assert_allclose(features[2, 3], TOOLBOX_CELL_2_3, atol=4e-3)
    np.testing.assert_allclose(features.sum(axis=(0, 1)), TOOLBOX_CHANNEL_SUMS, atol=0.03)
    np.testing.assert_allclose(features.sum(axis=2), TOOLBOX_CELL_SUMS, atol=0.03)


def test_draw_hog_puts_bar_along_the_edge():
    features = np.zeros((2, 3, 36), np.float32)
    features[1, 2, 0] = 0.2  # gradient angle 0 (vertical edge) in cell (1, 2)
    glyph = draw_hog(features, cell_px=16)
    assert glyph.shape == (32, 48)
    assert glyph.min() >= 0 and glyph.max() <= 1
    cell = glyph[16:32, 32:48]
    assert glyph[:16].max() == 0 and glyph[:, :32].max() == 0
    column_mass = cell.sum(axis=0)
    assert column_mass.argmax() in (7, 8)  # a vertical bar through the centre
    assert cell[:, 7:9].sum() > 0.9 * cell.sum()
