import numpy as np
import pytest

from corr_core.open3d_loader import load_open3d
from corr_core.alignment.render import camera_frames, render_views
from corr_core.geometry.primitives import rotate_about_y, rotation_about_y

N_VIEWS = 16
SIZE = 48


def merged_mesh(parts):
    """Concatenate (V, F) parts into one mesh."""
    vertices, faces, offset = [], [], 0
    for V, F in parts:
        vertices.append(V)
        faces.append(F + offset)
        offset += len(V)
    return np.concatenate(vertices), np.concatenate(faces)


def box(size, centre):
    o3d = load_open3d()
    mesh = o3d.geometry.TriangleMesh.create_box(*size)
    V = np.asarray(mesh.vertices) - np.asarray(size) / 2 + np.asarray(centre)
    return V, np.asarray(mesh.triangles)


def sphere(radius, centre, resolution=12):
    o3d = load_open3d()
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius, resolution)
    return np.asarray(mesh.vertices) + np.asarray(centre), np.asarray(mesh.triangles)


@pytest.fixture(scope="module")
def asymmetric_mesh():
    """Boxes and a ball at asymmetric places: no rotation about y maps it onto itself."""
    return merged_mesh(
        [
            box((0.5, 0.3, 0.2), (0.2, -0.2, 0.1)),
            box((0.1, 0.6, 0.1), (-0.35, 0.2, -0.3)),
            sphere(0.2, (0.1, 0.35, 0.45)),
        ]
    )


def test_camera_frames_are_rotated_copies():
    frames = camera_frames(N_VIEWS, 20.0)
    for frame in frames:
        np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-12)
        assert np.isclose(np.linalg.det(frame), 1.0)  # right-handed: right x up = back
    e = np.deg2rad(20.0)
    np.testing.assert_allclose(frames[0, 2], [0, np.sin(e), np.cos(e)], atol=1e-12)
    np.testing.assert_allclose(frames[3], frames[0] @ rotation_about_y(3 * 2 * np.pi / N_VIEWS).T, atol=1e-12)
    assert np.all(frames[:, 1, 1] > 0)  # image up has a +y component


def shift_errors(images_a, images_b):
    """Mean abs difference between roll(images_a, s) and images_b for every view shift s."""
    return np.array([np.abs(np.roll(images_a, s, axis=0) - images_b).mean() for s in range(len(images_a))])


@pytest.mark.parametrize("shift", [1, 5, 12])
def test_rotating_the_shape_shifts_the_views(asymmetric_mesh, shift):
    V, F = asymmetric_mesh
    base = render_views(V, F, n_views=N_VIEWS, image_size=SIZE)
    V_rotated = rotate_about_y(V, shift * 2 * np.pi / N_VIEWS)
    rotated = render_views(V_rotated, F, n_views=N_VIEWS, image_size=SIZE)
    errors = shift_errors(base, rotated)
    assert errors[shift] < 1e-3
    assert np.delete(errors, shift).min() > 20 * max(errors[shift], 1e-4)


def test_sphere_silhouette_and_shading():
    V, F = sphere(0.5, (0, 0, 0), resolution=40)
    images = render_views(V, F, n_views=4, image_size=SIZE, margin=1.0, ambient=0.1, diffuse=0.75)
    assert images.shape == (4, SIZE, SIZE) and images.dtype == np.float32
    radius_px = 0.5 / 1.0 * SIZE / 2
    object_pixels = (images < 1.0).sum(axis=(1, 2))
    np.testing.assert_allclose(object_pixels, np.pi * radius_px**2, rtol=0.05)
    centre = images[:, SIZE // 2 - 1 : SIZE // 2 + 1, SIZE // 2 - 1 : SIZE // 2 + 1]
    np.testing.assert_allclose(centre, 0.85, atol=0.02)  # facing the headlight: ambient + diffuse
    assert images[:, 0, 0].tolist() == [1.0] * 4
    assert images.min() >= 0.1 - 1e-6


def test_image_orientation_up_and_right():
    V, F = merged_mesh([box((0.2, 0.2, 0.2), (0.6, 0.5, 0.0))])  # up and to +x
    image = render_views(V, F, n_views=N_VIEWS, image_size=SIZE, elevation_deg=0.0)[0]  # camera on +z
    rows, cols = np.nonzero(image < 1.0)
    assert rows.max() < SIZE / 2  # world up is image up (row 0 = top)
    assert cols.min() > SIZE / 2  # +x is on the right when looking from +z


def test_shading_is_double_sided(asymmetric_mesh):
    V, F = asymmetric_mesh
    np.testing.assert_allclose(
        render_views(V, F, n_views=4, image_size=SIZE),
        render_views(V, F[:, ::-1], n_views=4, image_size=SIZE),
        atol=1e-6,
    )


def test_supersampling_and_input_checks(asymmetric_mesh):
    V, F = asymmetric_mesh
    images = render_views(V, F, n_views=2, image_size=SIZE, supersample=2)
    assert images.shape == (2, SIZE, SIZE)
    assert 0.0 <= images.min() and images.max() <= 1.0
    plain = render_views(V, F, n_views=2, image_size=SIZE)
    assert np.abs(images - plain).mean() < 0.05
    with pytest.raises(ValueError):
        render_views(V, F[:, :2])
    with pytest.raises(ValueError):
        render_views(V, F + len(V))
