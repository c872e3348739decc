"""Mesh reading keeps vertex ids in every format; unreadable files raise MeshError naming the file."""
import struct

import numpy as np
import pytest

from corr_core.geometry.mesh_io import (MeshError, _read_obj_lines, _read_plain_obj, load_mesh, normalize_mesh,
                                       save_obj)

# five vertices in a deliberately unsorted order: row i of V must be the file's i-th vertex
V5 = np.array([[3.0, 0.5, -1.0], [0.0, 0.0, 0.0], [1.0, 2.0, 0.25], [-2.0, 1.0, 1.0], [0.5, -1.5, 2.0]])


def test_obj_with_uv_normals_materials_groups_quads_and_negative_indices(tmp_path):
    path = tmp_path / "textured.obj"
    vertex_lines = "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V5.tolist())
    path.write_text(
        "# exported by a modeller\nmtllib missing.mtl\no body\n" + vertex_lines +
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nvn 1 0 0\n"
        "usemtl red\ng part_a\n"
        "f 1/1/1 2/2/1 3/3/1 4/4/1\n"      # quad, v/vt/vn
        "f 5/4/2 2/1/1 1/2/2\n"            # same vertices with other uv/normal: must not split vertices
        "usemtl blue\ng part_b\n"
        "f -1//1 -4//2 -3//1\n"            # negative indices, v//vn
        "f 3/4 4/1 5/2\n")                 # v/vt
    V, F = load_mesh(path)
    np.testing.assert_array_equal(V, V5)
    np.testing.assert_array_equal(F, [[0, 1, 2], [0, 2, 3], [4, 1, 0], [4, 1, 2], [2, 3, 4]])


def test_off_mixing_triangles_quads_and_pentagons(tmp_path):
    path = tmp_path / "mixed.off"
    path.write_text("OFF\n# comment\n5 3 0\n" + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in V5.tolist()) +
                    "4 0 1 2 3\n3 4 1 0\n5 0 1 2 3 4\n")
    V, F = load_mesh(path)
    np.testing.assert_array_equal(V, V5)
    np.testing.assert_array_equal(F, [[0, 1, 2], [0, 2, 3], [4, 1, 0], [0, 1, 2], [0, 2, 3], [0, 3, 4]])


def _ply_header(fmt: str, n_faces: int) -> str:
    return (f"ply\nformat {fmt} 1.0\nelement vertex {len(V5)}\nproperty float x\nproperty float y\n"
            f"property float z\nproperty uchar red\nelement face {n_faces}\n"
            "property list uchar int vertex_indices\nend_header\n")


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_ascii_and_binary_keep_vertex_order(tmp_path, fmt):
    faces = [[0, 1, 2, 3], [4, 1, 0]]
    path = tmp_path / f"scan_{fmt}.ply"
    if fmt == "ascii":
        body = "".join(f"{x!r} {y!r} {z!r} 7\n" for x, y, z in V5.tolist()) + "".join(
            f"{len(f)} {' '.join(map(str, f))}\n" for f in faces)
        path.write_bytes(_ply_header(fmt, len(faces)).encode() + body.encode())
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        body = b"".join(struct.pack(order + "fffB", *v, 7) for v in V5)
        body += b"".join(struct.pack(order + "B" + "i" * len(f), len(f), *f) for f in faces)
        path.write_bytes(_ply_header(fmt, len(faces)).encode() + body)
    V, F = load_mesh(path)
    np.testing.assert_array_equal(V, V5.astype(np.float32))
    # faces come grouped by polygon size; the triangles are the same
    assert sorted(map(tuple, np.sort(F, axis=1))) == sorted([(0, 1, 2), (0, 2, 3), (0, 1, 4)])


def test_stl_triangle_soup_is_merged_into_a_connected_mesh(tmp_path):
    import trimesh

    tet_v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    tet_f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    path = tmp_path / "part.stl"
    trimesh.Trimesh(tet_v, tet_f, process=False).export(path)
    V, F = load_mesh(path)
    assert V.shape == (4, 3) and F.shape == (4, 3)
    np.testing.assert_allclose(V[F], tet_v[tet_f])  # the same triangles, corner for corner


def test_glb_scene_becomes_one_mesh(tmp_path):
    import trimesh

    a = trimesh.Trimesh(V5[:3], [[0, 1, 2]], process=False)
    b = trimesh.Trimesh(V5[2:], [[0, 1, 2]], process=False)
    path = tmp_path / "scene.glb"
    trimesh.Scene([a, b]).export(path)
    V, F = load_mesh(path)
    assert V.shape == (6, 3) and F.shape == (2, 3)
    assert sorted(map(tuple, np.round(V[F].reshape(-1, 3), 5))) == sorted(
        map(tuple, np.round(np.vstack([V5[:3], V5[2:]]), 5)))


def test_many_vertices_in_random_order_roundtrip_exactly(tmp_path):
    rng = np.random.default_rng(3)
    V = rng.normal(size=(300, 3))
    F = np.stack([rng.permutation(300)[:3] for _ in range(200)])
    path = tmp_path / "random.obj"
    path.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V.tolist()) +
                    "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F))
    V2, F2 = load_mesh(path)
    np.testing.assert_array_equal(V2, V)
    np.testing.assert_array_equal(F2, F)


TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
PLAIN_OBJ = {  # the layout read in vectorized passes
    "save_obj": None,  # written by save_obj (below)
    "faces_first": "f 2 3 1\n" + TRIANGLE,
    "blank_lines_tabs_no_final_newline": "\n" + TRIANGLE.replace("v 1 0 0", " v\t1  0 0\t") + "\n  \nf 1 2 3",
    "signs_exponents_underscores_nan_inf": ("v +1.5e-3 -0 .5\nv 1_0 2 -3\nv 4 1E2 7\n"
                                            "v nan inf -inf\nf +1 2 3\nf 3 2 1\n"),  # NaN unused: no error
    "vertices_only": TRIANGLE,
}
OTHER_OBJ = {  # anything else: read line by line
    "crlf": TRIANGLE.replace("\n", "\r\n") + "f 1 2 3\r\n",
    "comment": "# made by hand\n" + TRIANGLE + "f 1 2 3\n",
    "normals": TRIANGLE + "vn 0 0 1\nf 1//1 2//1 3//1\n",
    "quad": TRIANGLE + "v 1 1 0\nf 1 2 4 3\n",
    "relative": TRIANGLE + "f -3 -2 -1\n",
    "fourth_coordinate": "v 0 0 0 1\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "two_vertices_on_a_line": "v 0 0 0 v 1 0 0\n\nv 0 1 0\nf 1 2 2\n",  # the line reader keeps one
    "non_ascii_name": TRIANGLE + "o caf\u00e9\nf 1 2 3\n",
    "form_feed": TRIANGLE.replace("\n", "\x0c\n", 1) + "f 1 2 3\n",
}


@pytest.mark.parametrize("name", sorted(PLAIN_OBJ) + sorted(OTHER_OBJ))
def test_the_vectorized_obj_reader_reads_exactly_what_the_line_reader_reads(tmp_path, name):
    path = tmp_path / f"{name}.obj"
    if name == "save_obj":
        rng = np.random.default_rng(5)
        save_obj(path, rng.normal(size=(50, 3)), rng.integers(0, 50, size=(80, 3)))
    else:
        path.write_bytes(({**PLAIN_OBJ, **OTHER_OBJ}[name]).encode("utf-8"))
    plain = _read_plain_obj(path.read_bytes())
    assert (plain is not None) == (name in PLAIN_OBJ)  # the plain layout is recognized, nothing else is
    V, F = _read_obj_lines(path)
    got = load_mesh(path, require_faces=False)
    for a, b in zip(got, (V, F)):
        assert a.dtype == b.dtype and a.shape == b.shape
        np.testing.assert_array_equal(a, b)
    if plain is not None:
        np.testing.assert_array_equal(plain[0], V)
        np.testing.assert_array_equal(plain[1], F)


@pytest.mark.parametrize("name, text, message", [
    ("empty.obj", "", "no vertices"),
    ("points.obj", "v 0 0 0\nv 1 0 0\n", "no faces"),
    ("garbage.off", "OFF\n3 1 0\n0 0 0\n1 x 0\n", "cannot parse"),
    ("short.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n", "ends early"),
    ("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "NaN or infinite"),
    ("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "outside 0..2"),
    ("zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "index 0"),
    ("broken.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n", "cannot parse"),
    ("mesh.xyz", "0 0 0\n", "unknown mesh format"),
])
def test_unusable_files_raise_mesh_error_naming_the_file(tmp_path, name, text, message):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(MeshError, match=message) as info:
        load_mesh(path)
    assert name in str(info.value)


def test_nan_in_an_unreferenced_vertex_is_not_an_error(tmp_path):
    path = tmp_path / "stray.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan nan nan\nf 1 2 3\n")
    V, F = load_mesh(path)
    assert len(V) == 4 and np.isnan(V[3]).all()


@pytest.mark.parametrize("center", ["bbox", "mean", "area"])
def test_normalize_ignores_unreferenced_vertices(center):
    rng = np.random.default_rng(0)
    V = rng.normal(size=(50, 3))
    F = np.stack([np.arange(0, 48), np.arange(1, 49), np.arange(2, 50)], axis=1)
    far = np.vstack([V, np.full((10, 3), 1000.0), [[1e30, 0, 0]]])
    Vn, c, r = normalize_mesh(V, center=center, F=F)
    Vn_far, c_far, r_far = normalize_mesh(far, center=center, F=F)
    np.testing.assert_array_equal(Vn_far[:50], Vn)
    assert (c_far, r_far) == (pytest.approx(c), r)


def test_save_obj_roundtrip(tmp_path):
    F = np.array([[0, 1, 2], [0, 2, 3]])
    save_obj(tmp_path / "m.obj", V5, F)
    V, F2 = load_mesh(tmp_path / "m.obj")
    np.testing.assert_allclose(V, V5, rtol=1e-8)
    np.testing.assert_array_equal(F2, F)


def test_save_obj_writes_each_coordinate_as_9_significant_digits_and_1_based_faces(tmp_path):
    """The bytes are those of ``v {x:.9g} {y:.9g} {z:.9g}`` / ``f {a+1} {b+1} {c+1}`` lines (files written by
    earlier versions stay byte-identical), for float64 and float32 vertices, int32 faces and special values."""
    rng = np.random.default_rng(3)
    V = rng.standard_normal((300, 3)) * 10.0 ** rng.integers(-9, 9, size=(300, 3))
    V[:3] = [[0.0, -0.0, np.nan], [np.inf, -np.inf, 1e-320], [1 / 3, 2 / 3, 123456789.125]]
    F = rng.integers(0, 300, size=(500, 3))
    for V_, F_ in ((V, F), (V.astype(np.float32), F.astype(np.int32))):
        save_obj(tmp_path / "m.obj", V_, F_)
        expected = ("".join(f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in V_)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F_))
        assert (tmp_path / "m.obj").read_text() == expected
    save_obj(tmp_path / "points.obj", V[:2], [])
    assert (tmp_path / "points.obj").read_text() == "v 0 -0 nan\nv inf -inf 9.99988867e-321\n"   # a subnormal
    with pytest.raises(ValueError, match="points2.obj"):
        save_obj(tmp_path / "points2.obj", V[:, :2], F)
