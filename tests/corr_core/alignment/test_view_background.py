"""A grayscale (or blue-free colour) view is background-masked like the course's blue-background RGB view."""
import numpy as np
import pytest
from PIL import Image

from corr_core.alignment.views import BACKGROUND_RGB, background_color, load_view_image
from tests.helpers import COURSE_DATA


def _blue_view(height=90, width=70) -> np.ndarray:
    """(H, W, 3) uint8: pure-blue background, a shaded object (grays 40..220) touching the left border."""
    rgb = np.zeros((height, width, 3), np.uint8)
    rgb[...] = BACKGROUND_RGB
    yy, xx = np.mgrid[:height, :width]
    body = ((yy - 45) ** 2 / 30 ** 2 + (xx - 30) ** 2 / 28 ** 2) < 1
    leg = (xx < 12) & (yy > 60)  # the object reaches the border, as in the course's cropped views
    shade = (40 + 180 * xx / width).astype(np.uint8)
    for mask in (body, leg):
        rgb[mask] = shade[mask][:, None]
    return rgb


@pytest.mark.parametrize("mode", ["L", "LA", "P"])
def test_converted_view_masks_the_same_object(tmp_path, mode):
    rgb = _blue_view()
    Image.fromarray(rgb).save(tmp_path / "001_0.png")
    Image.fromarray(rgb).convert(mode).save(tmp_path / "002_0.png")
    reference, converted = load_view_image(tmp_path / "001_0.png"), load_view_image(tmp_path / "002_0.png")
    assert 0.2 < np.mean(reference < 1) < 0.6
    assert np.mean(converted < 1) == pytest.approx(np.mean(reference < 1), abs=0.01)


def test_background_color_rules():
    rgb = _blue_view()
    assert background_color(rgb, "RGB") == BACKGROUND_RGB
    gray = np.asarray(Image.fromarray(rgb).convert("L").convert("RGB"))
    assert background_color(gray, "L") == (29, 29, 29)  # ITU-R 601 luma of pure blue
    assert background_color(gray, "RGB") == BACKGROUND_RGB  # a colour view: only pure blue is background


@pytest.mark.course
def test_course_view_converted_to_grayscale_matches(tmp_path):
    source = COURSE_DATA / "chairs_rendering" / "007_3.png"
    Image.open(source).convert("L").save(tmp_path / "gray.png")
    assert np.mean(load_view_image(tmp_path / "gray.png") < 1) == pytest.approx(
        np.mean(load_view_image(source) < 1), abs=0.005)
