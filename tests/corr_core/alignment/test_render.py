import numpy as np
import pytest

from corr_core.open3d_loader import load_open3d
from corr_core.alignment.render import camera_frames, pixels_in_face_boxes, render_views, view_rays
from corr_core.generate.chairs import canonical_chair
from corr_core.geometry.mesh_io import normalize_mesh
from corr_core.geometry.primitives import face_normals, rotate_about_y, rotation_about_y

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
    frames = camera_frames(n_views=N_VIEWS, elevation_deg=20.0)
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


def render_every_ray(V, F, n_views=16, image_size=120, elevation_deg=20.0, margin=1.05, ambient=0.1, diffuse=0.75):
    """Reference: every pixel's ray cast (no culling), shaded as the module docstring says."""
    o3d = load_open3d()
    V = np.asarray(V, dtype=np.float32)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(V), o3d.core.Tensor(np.asarray(F).astype(np.uint32)))
    rays = view_rays(n_views=n_views, image_size=image_size, elevation_deg=elevation_deg, margin=margin)
    face = scene.cast_rays(o3d.core.Tensor(rays))["primitive_ids"].numpy()
    hit = face != scene.INVALID_ID
    backs = camera_frames(n_views=n_views, elevation_deg=elevation_deg)[:, 2].astype(np.float32)
    shade = ambient + diffuse * np.abs(np.einsum("fi,vi->fv", face_normals(V, F).astype(np.float32), backs))
    images = np.ones(face.shape, np.float32)
    images[hit] = shade[face[hit], np.nonzero(hit)[0]]
    return images, hit


def culling_cases(asymmetric_mesh):
    """(name, V, F): a chair, the boxes and ball, and meshes partly or wholly outside the view window."""
    chair = canonical_chair(0, 3)
    chair = (normalize_mesh(chair[0], "area", chair[1])[0], chair[1])
    V, F = asymmetric_mesh
    return [("chair", *chair), ("turned chair", rotate_about_y(chair[0], 0.7) * 0.9, chair[1]),
            ("boxes and ball", V, F), ("partly outside", 1.6 * V + [0.6, -0.3, 0.2], F),
            ("outside", V + [5.0, 0.0, 0.0], F),
            ("tiny triangle", V[F[:1]].reshape(3, 3) * 1e-3, np.array([[0, 1, 2]])),
            ("one triangle", np.array([[-0.7, -0.5, 0.1], [0.6, -0.2, -0.3], [0.1, 0.8, 0.2]]), np.array([[0, 1, 2]]))]


def test_rays_cast_only_where_a_face_can_be_hit_give_the_same_views(asymmetric_mesh):
    for name, V, F in culling_cases(asymmetric_mesh):
        for kwargs in ({}, {"n_views": 5, "image_size": 48, "elevation_deg": -35.0, "margin": 0.8}):
            reference, hit = render_every_ray(V, F, **kwargs)
            np.testing.assert_array_equal(render_views(V, F, **kwargs), reference, err_msg=name)
            cast = pixels_in_face_boxes(np.asarray(V, np.float32), F, **{"n_views": 16, **kwargs})
            assert not np.any(hit & ~cast), name  # every pixel whose ray hits is cast
    V, F = culling_cases(asymmetric_mesh)[0][1:]
    cast = pixels_in_face_boxes(V, F)
    assert 0.05 < cast.mean() < 0.4  # a chair: a small part of every view, not the whole window


def test_supersampled_culled_views_are_the_box_average_of_every_ray(asymmetric_mesh):
    V, F = asymmetric_mesh
    fine, _ = render_every_ray(V, F, n_views=3, image_size=2 * SIZE)
    expected = fine.reshape(3, SIZE, 2, SIZE, 2).mean(axis=(2, 4))
    np.testing.assert_array_equal(render_views(V, F, n_views=3, image_size=SIZE, supersample=2), expected)


def test_the_rays_of_chosen_views_are_those_views_rays_bit_for_bit():
    kwargs = {"n_views": 8, "image_size": 20, "elevation_deg": 10.0, "margin": 1.05}
    every = view_rays(**kwargs)
    chosen = view_rays(**kwargs, views=(5, 1))
    assert chosen.shape == (2, 20, 20, 6) and chosen.dtype == np.float32
    np.testing.assert_array_equal(chosen, every[[5, 1]])
