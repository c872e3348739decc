"""Shapes from mixed sources through align.views: a declared up axis, very different scales and mesh
densities, and quad/polygon OBJ files with materials, texture coordinates and normals."""

import numpy as np
import pytest

from corr_core.alignment.azimuth import UP_AXES, agreement_up_to_offset, to_y_up
from corr_core.alignment.pair_costs import pair_costs
from corr_core.alignment.solvers import solve_alignment
from corr_core.generate.chairs import canonical_chair
from corr_core.geometry.mesh_io import save_obj
from corr_core.geometry.primitives import rotate_about_y
from shapecorr.alignment import _check_views, hog, views

pytestmark = pytest.mark.filterwarnings("ignore:.*flipped.*:UserWarning")  # repairs of generated boxes


def render(path, **kw):
    return views([str(path)], image_size=64, **kw)["views"].astype(np.float64) / 255.0


def subdivide(V, F):
    """Each triangle split into 4 at its edge midpoints (the same surface, 4x the triangles)."""
    a, b, c = F.T
    n = len(V)
    mids = np.concatenate([(V[a] + V[b]) / 2, (V[b] + V[c]) / 2, (V[c] + V[a]) / 2])
    ab, bc, ca = n + np.arange(len(F)), n + len(F) + np.arange(len(F)), n + 2 * len(F) + np.arange(len(F))
    F4 = np.concatenate([np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1), np.stack([ca, bc, c], 1),
                         np.stack([ab, bc, ca], 1)])
    return np.concatenate([V, mids]), F4


@pytest.mark.parametrize("up", ["z", "x"])
def test_declared_up_axis_gives_the_views_of_the_y_up_shape(tmp_path, up):
    V, F = canonical_chair(0, 1)
    save_obj(tmp_path / "y.obj", V, F)
    save_obj(tmp_path / "other.obj", V @ UP_AXES[up], F)          # stored with `up` as the up axis
    np.testing.assert_allclose(to_y_up(V @ UP_AXES[up], up), V, atol=1e-12)
    reference = render(tmp_path / "y.obj")
    assert np.abs(render(tmp_path / "other.obj", up=up) - reference).max() < 0.01
    assert np.abs(render(tmp_path / "other.obj") - reference).mean() > 0.05  # read as y up it is lying down


def test_an_unknown_up_axis_is_refused_by_name():
    with pytest.raises(ValueError, match="parameter 'up' = 'w'.*'x', 'y', 'z'"):
        _check_views(n_views=16, image_size=64, elevation_deg=20.0, center="area", up="w")
    with pytest.raises(ValueError, match="up axis 'w'"):
        to_y_up(np.zeros((1, 3)), "w")


def test_scale_position_and_mesh_density_do_not_change_the_views(tmp_path):
    V, F = canonical_chair(0, 2)
    save_obj(tmp_path / "a.obj", V, F)
    Vd, Fd = subdivide(V, F)
    save_obj(tmp_path / "b.obj", Vd * 750.0 + np.array([120.0, -40.0, 3.0]), Fd)   # millimetres, offset, 4x faces
    save_obj(tmp_path / "c.obj", V * 0.002 - 5.0, F)                                # tiny and far away
    reference = render(tmp_path / "a.obj")
    for name in ("b.obj", "c.obj"):
        assert np.abs(render(tmp_path / name) - reference).mean() < 0.002, name


def mixed_collection(tmp_path, steps):
    """Chairs 1..len(steps) rotated by steps (16 per turn), each saved at a different scale and density."""
    files = []
    for i, s in enumerate(steps, start=1):
        V, F = canonical_chair(0, i)
        V = rotate_about_y(V, 2 * np.pi * s / 16)
        if i % 2:
            V, F = subdivide(V, F)
        save_obj(tmp_path / f"{i:03d}.obj", V * 10.0 ** (i % 4 - 1) + i, F)
        files.append(tmp_path / f"{i:03d}.obj")
    return files


def test_a_collection_of_mixed_scales_and_densities_aligns(tmp_path):
    steps = np.random.default_rng(5).integers(0, 16, 8)
    files = mixed_collection(tmp_path, steps)
    C = pair_costs(np.stack([hog(views([str(f)], image_size=96)) for f in files]))
    assert agreement_up_to_offset(solve_alignment(C, solver="spectral")["labels"], steps, 16)[0] == 1.0


def box_quads(center, half, first):
    """8 corners (8, 3) and 6 quads (1-based OBJ ids from ``first``) of an axis-aligned box."""
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.asarray(center) + signs * np.asarray(half), [[first + q for q in quad] for quad in quads]


def write_polygon_chair(path, angle):
    """An OBJ of a simple chair (seat, backrest, four legs) made of quads and a hexagonal foot plate (one
    6-gon face), with mtllib/usemtl, groups, vt/vn and f v/vt/vn tokens; rotated about +y by ``angle``."""
    parts = [([0, 0.45, 0], [0.25, 0.03, 0.22]), ([0, 0.8, -0.2], [0.25, 0.32, 0.03])]
    parts += [([x, 0.21, z], [0.03, 0.21, 0.03]) for x in (-0.2, 0.2) for z in (-0.18, 0.18)]
    verts, faces = [], []
    for center, half in parts:
        v, q = box_quads(center, half, len(verts) + 1)
        verts.extend(v)
        faces.extend(q)
    hexagon = [[0.35 + 0.08 * np.cos(t), 0.0, 0.3 + 0.08 * np.sin(t)] for t in np.arange(6) * np.pi / 3]
    faces.append(list(range(len(verts) + 1, len(verts) + 7)))
    verts.extend(hexagon)
    V = rotate_about_y(np.array(verts), angle)
    lines = ["# exported by a modelling tool", "mtllib chair.mtl", "o chair", "g frame", "usemtl wood"]
    lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in V] + ["vt 0 0", "vt 1 0", "vn 0 1 0", "s off"]
    for k, f in enumerate(faces):
        if k == len(faces) - 1:
            lines.append("usemtl metal")
        lines.append("f " + " ".join(f"{i}/{1 + j % 2}/1" for j, i in enumerate(f)))
    path.write_text("\n".join(lines) + "\n")
    (path.parent / "chair.mtl").write_text("newmtl wood\nKd 0.6 0.4 0.2\nnewmtl metal\nKd 0.5 0.5 0.5\n")


def test_quad_and_polygon_obj_with_materials_aligns(tmp_path):
    steps = [0, 3, 7, 12, 5]
    for i, s in enumerate(steps):
        write_polygon_chair(tmp_path / f"{i:03d}.obj", 2 * np.pi * s / 16)
    F = np.stack([hog(views([str(tmp_path / f"{i:03d}.obj")], image_size=96)) for i in range(len(steps))])
    sol = solve_alignment(pair_costs(F), solver="spectral")
    assert sol["symmetry_order"].tolist() == [1] * len(steps)
    assert agreement_up_to_offset(sol["labels"], np.array(steps), 16)[0] == 1.0


def test_export_writes_y_up_meshes_turned_by_the_continuous_angle(tmp_path):
    from corr_core.alignment.azimuth import align_vertices_deg
    from corr_core.geometry.mesh_io import load_mesh, normalize_mesh
    from shapecorr.alignment import export

    V, F = canonical_chair(0, 3)
    save_obj(tmp_path / "z.obj", V @ UP_AXES["z"], F)                # stored z up
    solution = {"names": ["z"], "labels": [1], "n_views": 16, "angles_deg": [23.4], "symmetry_order": [1]}
    (tmp_path / "out").mkdir()  # the engine creates a stage's out_dir
    export({"z": str(tmp_path / "z.obj")}, solution, up="z", out_dir=str(tmp_path / "out"))
    Va, _ = load_mesh(tmp_path / "out" / "aligned_meshes" / "z.obj")
    Vn, _, _ = normalize_mesh(V, center="area", F=F)
    np.testing.assert_allclose(Va, align_vertices_deg(Vn, 23.4), atol=1e-6)
    assert (tmp_path / "out" / "alignment.csv").read_text().splitlines()[1] == "z,1,23.40,1"
