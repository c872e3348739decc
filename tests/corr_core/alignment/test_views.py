from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from corr_core.alignment.views import (
    crop_to_object,
    find_view_files,
    load_view_image,
    load_view_stack,
    pad_to_square,
    to_gray_white_background,
)

from tests.helpers import COURSE_DATA

COURSE_VIEWS = COURSE_DATA / "chairs_rendering"
BLUE = (0, 0, 255)


def write_view(path, height=80, width=40, gray=128, palette=True, box=None):
    """Blue-background PNG with a gray rectangle ``box`` = (top, bottom, left, right)."""
    rgb = np.zeros((height, width, 3), np.uint8)
    rgb[:] = BLUE
    top, bottom, left, right = box or (0, height, 0, width)
    rgb[top:bottom, left:right] = gray
    image = Image.fromarray(rgb)
    if palette:
        image = image.convert("P", palette=Image.Palette.ADAPTIVE, colors=4)
    image.save(path)
    return rgb


def test_gray_conversion_and_background():
    rgb = np.array([[BLUE, (255, 0, 0)], [(0, 255, 0), (10, 20, 30)]], np.uint8)
    gray = to_gray_white_background(rgb)
    expected = np.array([[1.0, 0.299], [0.587, (0.299 * 10 + 0.587 * 20 + 0.114 * 30) / 255]])
    np.testing.assert_allclose(gray, expected, atol=1e-6)


def test_pad_to_square_centres():
    image = np.zeros((2, 6), np.float32)
    padded = pad_to_square(image)
    assert padded.shape == (6, 6)
    np.testing.assert_array_equal(padded[2:4], 0.0)
    np.testing.assert_array_equal(padded[[0, 1, 4, 5]], 1.0)


@pytest.mark.parametrize("palette", [True, False])
def test_load_view_image_tall_object(tmp_path, palette):
    path = tmp_path / "003_2.png"
    write_view(path, height=80, width=40, gray=128, palette=palette)  # all object, no background
    image = load_view_image(path, size=40)
    assert image.shape == (40, 40) and image.dtype == np.float32
    # 80x80 after padding: object in columns 20..60 -> 10..30 at size 40, white on both sides
    np.testing.assert_allclose(image[:, 12:28], 128 / 255, atol=1e-3)
    np.testing.assert_allclose(image[:, :9], 1.0, atol=1e-6)
    np.testing.assert_allclose(image[:, 31:], 1.0, atol=1e-6)


def test_load_view_image_background_becomes_white(tmp_path):
    path = tmp_path / "001_0.png"
    write_view(path, height=60, width=60, gray=50, box=(20, 40, 10, 30))
    image = load_view_image(path, size=60)  # no resize: exact
    np.testing.assert_allclose(image[20:40, 10:30], 50 / 255, atol=1e-6)
    mask = np.ones((60, 60), bool)
    mask[20:40, 10:30] = False
    np.testing.assert_allclose(image[mask], 1.0, atol=1e-6)


def test_load_view_image_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope_0.png"):
        load_view_image(tmp_path / "nope_0.png")
    bad = tmp_path / "bad_0.png"
    bad.write_bytes(b"this is not a png")
    with pytest.raises(ValueError, match="bad_0.png"):
        load_view_image(bad)


def test_load_view_stack_keeps_order(tmp_path):
    paths = []
    for gray in (30, 90, 200):
        path = tmp_path / f"005_{gray}.png"
        write_view(path, height=16, width=16, gray=gray)
        paths.append(str(path))
    stack = load_view_stack(paths[::-1], size=16)
    assert stack.shape == (3, 16, 16)
    np.testing.assert_allclose(stack[:, 8, 8], [200 / 255, 90 / 255, 30 / 255], atol=1e-6)
    with pytest.raises(ValueError):
        load_view_stack([])


def touch_views(folder, item, views):
    for view in views:
        (folder / f"{item}_{view}.png").write_bytes(b"")


def test_find_view_files_sorts_numerically(tmp_path):
    touch_views(tmp_path, "001", range(16))
    touch_views(tmp_path, "002", range(16))
    (tmp_path / "notes.txt").write_text("ignored")
    found = find_view_files(tmp_path)
    assert list(found) == ["001", "002"]
    assert [Path(p).name for p in found["002"]] == [f"002_{k}.png" for k in range(16)]


def test_find_view_files_names_missing_views(tmp_path):
    touch_views(tmp_path, "001", range(16))
    touch_views(tmp_path, "007", [k for k in range(16) if k != 4])
    with pytest.raises(ValueError, match=r"item 007 is missing views \[4\]"):
        find_view_files(tmp_path)
    with pytest.raises(ValueError, match="001"):
        find_view_files(tmp_path, n_views=17)


def test_find_view_files_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        find_view_files(tmp_path / "missing")
    with pytest.raises(ValueError, match="no <item>_<view>.png"):
        find_view_files(tmp_path)


def test_crop_to_object_fills_the_frame():
    image = np.ones((100, 100), np.float32)
    image[10:30, 60:70] = 0.4  # 20 tall, 10 wide, off-centre
    cropped = crop_to_object(image, size=40)
    assert cropped.shape == (40, 40)
    rows, cols = np.nonzero(cropped < 0.9)
    assert rows.min() <= 1 and rows.max() >= 38  # object spans the full height
    assert abs((cols.min() + cols.max()) / 2 - 19.5) <= 1.0  # and is centred horizontally
    np.testing.assert_allclose(crop_to_object(np.ones((30, 30)), size=10), 1.0)


@pytest.mark.course
@pytest.mark.skipif(not COURSE_VIEWS.is_dir(), reason=f"course data not found at {COURSE_VIEWS}")
def test_course_chair_views():
    found = find_view_files(COURSE_VIEWS)
    assert len(found) == 100
    assert all(len(paths) == 16 for paths in found.values())
    assert Path(found["007"][10]).name == "007_10.png"
    stack = load_view_stack(found["001"], size=120)
    assert stack.shape == (16, 120, 120)
    assert 0.0 <= stack.min() and stack.max() <= 1.0
    np.testing.assert_allclose(stack[:, 0, 0], 1.0)  # background became white
    object_fraction = (stack < 0.95).mean(axis=(1, 2))
    assert np.all(object_fraction > 0.1) and np.all(object_fraction < 0.9)
