"""Repair on load: duplicated / degenerate / zero-area faces go, orientation is made consistent, unreferenced
vertices are ignored, vertex ids never change, every repair is reported naming the file."""
import warnings

import re

import numpy as np
import pytest

from corr_core.generate.chairs import canonical_chair
from corr_core.generate.defects import cut_along_a_seam, with_fins
from corr_core.geometry.mesh_io import MeshError, save_obj
from corr_core.geometry.repair import RepairRecord, load_repaired_mesh, orient_faces, repair_mesh
from tests.helpers import logged, sphere


TET_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def _kinds(records):
    """{kind: record} of ``RepairRecord``s or of their stored dicts (a stage result's "repairs")."""
    return {r["kind"]: r for r in (r.as_dict() if isinstance(r, RepairRecord) else r for r in records)}


def _published_scan(V, F, flips=(0, 5, 9)):
    """The published-scan defects: one face duplicated in both orientations, 10 unreferenced far vertices and
    one at 1e30, a few faces flipped. Returns (V2, F2); vertex ids 0..n-1 are those of V."""
    F2 = F.copy()
    F2[list(flips)] = F2[list(flips)][:, ::-1]
    F2 = np.vstack([F2, F[7], F[7][::-1]])
    V2 = np.vstack([V, np.full((10, 3), 40.0) + np.arange(10)[:, None], [[1e30, 0.0, 0.0]]])
    return V2, F2


def test_clean_mesh_needs_no_repair():
    V, F = sphere(300)
    F2, records = repair_mesh(V, F, "ball.obj")
    np.testing.assert_array_equal(F2, F)
    assert records == []


def test_published_scan_repairs_are_reported_and_keep_vertex_ids():
    V, F = sphere(400)
    V2, F2 = _published_scan(V, F)
    repaired, records = repair_mesh(V2, F2, "scan.obj")
    np.testing.assert_array_equal(repaired, F)  # the original faces, original orientation, original ids
    kinds = _kinds(records)
    assert kinds["duplicate_faces"]["count"] == 2 and "1 opposite orientation" in kinds["duplicate_faces"]["message"]
    assert kinds["reoriented_faces"]["count"] == 3
    assert kinds["unreferenced_vertices"]["count"] == 11
    assert all(r.message.startswith("scan.obj: ") and r.file == "scan.obj" for r in records)


def test_published_chair_loads_renders_at_normal_size_and_reports(tmp_path):
    from shapecorr.alignment import views

    V, F = canonical_chair(0, 1)
    F, _ = repair_mesh(V, F, "chair")  # the generated chair's faces are not consistently oriented
    save_obj(tmp_path / "clean.obj", V, F)
    V2, F2 = _published_scan(V, F)
    save_obj(tmp_path / "scan.obj", V2, F2)
    clean = views(str(tmp_path / "clean.obj"), n_views=4, image_size=64)
    with logged() as messages:
        scan = views(str(tmp_path / "scan.obj"), n_views=4, image_size=64)
    assert any(re.search(r"scan\.obj: dropped 2 duplicate faces", m) for m in messages)
    object_fraction = lambda out: float(np.mean(out["views"] < 255))  # noqa: E731
    assert object_fraction(clean) > 0.05
    assert object_fraction(scan) == pytest.approx(object_fraction(clean), rel=0.02)
    assert np.mean(np.abs(scan["views"].astype(float) - clean["views"])) < 1.0
    kinds = _kinds(scan["repairs"])
    assert {"duplicate_faces", "reoriented_faces", "unreferenced_vertices"} <= set(kinds)
    assert str(tmp_path / "scan.obj") in kinds["duplicate_faces"]["message"]
    assert clean["repairs"] == [] or all(r["level"] == "note" for r in clean["repairs"])


def test_a_duplicated_face_pair_is_dropped_and_the_correspondence_mesh_kept(tmp_path):
    """A face repeated in both orientations is dropped, not taken for '2 non-manifold edge(s) shared by more than
    two faces' that would reject the mesh."""
    from shapecorr.correspondence import mesh

    V, F = sphere(300)
    save_obj(tmp_path / "mesh001.obj", V, np.vstack([F, F[3], F[3][::-1]]))
    with logged() as messages:
        out = mesh(str(tmp_path / "mesh001.obj"))
    assert any(m.startswith("mesh001.obj: dropped 2 duplicate faces (") for m in messages)
    np.testing.assert_array_equal(out["F"], F)
    assert [r["kind"] for r in out["repairs"]] == ["duplicate_faces"]
    assert out["area"] == pytest.approx(4 * np.pi, rel=0.02)


def test_degenerate_and_zero_area_faces_are_dropped():
    V = np.vstack([TET_V, [[0.5, 0.5, 0.0]]])  # vertex 4 lies on the edge (1, 2): face (1, 2, 4) has no area
    F = np.vstack([TET_F, [[0, 0, 1]], [[1, 2, 4]]])
    F2, records = repair_mesh(V, F, "flat.obj")
    np.testing.assert_array_equal(F2, TET_F)
    kinds = _kinds(records)
    assert kinds["degenerate_faces"]["count"] == 1 and "face 4" in kinds["degenerate_faces"]["message"]
    assert kinds["zero_area_faces"]["count"] == 1 and "face 5" in kinds["zero_area_faces"]["message"]


def test_orientation_keeps_the_majority_and_flips_the_rest():
    V, F = sphere(500)
    rng = np.random.default_rng(1)
    flipped = rng.choice(len(F), size=len(F) // 3, replace=False)
    bad = F.copy()
    bad[flipped] = bad[flipped][:, ::-1]
    fixed, n_flipped, n_inconsistent = orient_faces(bad)
    assert n_flipped == len(flipped) and n_inconsistent == 0
    normals = np.cross(V[fixed[:, 1]] - V[fixed[:, 0]], V[fixed[:, 2]] - V[fixed[:, 0]])
    assert np.all(np.einsum("ij,ij->i", normals, V[fixed].mean(1)) > 0)  # all outward again
    np.testing.assert_array_equal(np.sort(fixed, axis=1), np.sort(F, axis=1))  # same triangles, same rows


def test_orientation_is_per_component():
    _, F = sphere(200)
    n = int(F.max()) + 1
    F2 = np.vstack([F, F[:, ::-1] + n])  # a second ball, consistently inward: a patch of its own, kept as is
    F2[[0, len(F) + 1]] = F2[[0, len(F) + 1]][:, ::-1]  # one stray flip in each ball
    fixed, n_flipped, _ = orient_faces(F2)
    assert n_flipped == 2
    np.testing.assert_array_equal(fixed, np.vstack([F, F[:, ::-1] + n]))


def test_outward_turns_an_inward_surface_and_leaves_outward_surfaces_and_sheets_alone():
    V, F = sphere(500)
    inward = np.ascontiguousarray(F[:, ::-1])
    fixed, records = repair_mesh(V, inward, "ball.obj", outward=True)
    np.testing.assert_array_equal(fixed, F)                                       # every face back outward
    assert [r.kind for r in records] == ["reoriented_outward"] and records[0].level == "repair"
    assert "ball.obj" in records[0].message and "outward" in records[0].message
    np.testing.assert_array_equal(repair_mesh(V, inward, "ball.obj")[0], inward)  # off by default
    fixed, records = repair_mesh(V, F, "ball.obj", outward=True)
    np.testing.assert_array_equal(fixed, F)
    assert records == []
    cap = F[V[F].mean(axis=1)[:, 2] > 0.5]                                        # an open piece: its convex
    np.testing.assert_array_equal(repair_mesh(V, cap[:, ::-1], "cap.obj", outward=True)[0], cap)   # side is out
    x, y = np.meshgrid(np.arange(5.0), np.arange(5.0))
    P = np.column_stack([x.ravel(), y.ravel(), np.zeros(25)])
    i = (np.arange(4)[:, None] * 5 + np.arange(4)[None, :]).ravel()
    sheet = np.vstack([np.column_stack([i, i + 1, i + 6]), np.column_stack([i, i + 6, i + 5])])
    for flat in (sheet, np.ascontiguousarray(sheet[:, ::-1])):                    # flat: no side to choose
        np.testing.assert_array_equal(repair_mesh(P, flat, "sheet.obj", outward=True)[0], flat)


def test_keep_largest_component_keeps_vertex_ids():
    V, F = sphere(300)
    small = TET_V * 0.1 + [3.0, 0, 0]
    V2 = np.vstack([V, small])
    F2 = np.vstack([F, TET_F + len(V)])
    kept, records = repair_mesh(V2, F2, "two.obj", keep_largest_component=True)
    np.testing.assert_array_equal(kept, F)
    kinds = _kinds(records)
    assert kinds["components"]["action"] == "dropped" and "unreferenced_vertices" not in kinds
    assert (f"kept the largest of 2 components: {len(V)} of {len(V) + 4} vertices; 4 vertices in 1 small piece "
            "ignored (4 faces,") in kinds["components"]["message"]
    _, records = repair_mesh(V2, F2, "two.obj")
    assert _kinds(records)["components"]["level"] == "note"


def test_weld_merges_the_copies_of_a_seam_into_one_surface_and_keeps_vertex_ids(tmp_path):
    """A sphere cut along its equator (the upper faces get their own copies of the equator's vertices, appended):
    two pieces with a boundary each. ``weld`` re-points the faces to the originals (the file's faces back, the
    copies used by no face), so the correspondence stage keeps the whole sphere, not the larger half."""
    from corr_core.geometry.repair import coincident_representatives
    from shapecorr.correspondence import mesh

    V, F = sphere(300)
    V_cut, F_cut, seam, _ = cut_along_a_seam(V, F, V[F].mean(axis=1)[:, 2] > 0)
    rep = coincident_representatives(V_cut, F_cut)
    np.testing.assert_array_equal(rep[len(V):], seam)
    np.testing.assert_array_equal(rep[:len(V)], np.arange(len(V)))
    welded, records = repair_mesh(V_cut, F_cut, "cut.obj", weld=True)
    np.testing.assert_array_equal(welded, F)
    kinds = _kinds(records)
    assert kinds["coincident_vertices"]["count"] == len(seam) and "boundary" not in kinds
    assert "unreferenced_vertices" not in kinds                       # the file's faces used every vertex
    _, records = repair_mesh(V_cut, F_cut, "cut.obj")
    assert "coincident_vertices" not in _kinds(records) and "boundary" in _kinds(records)
    save_obj(tmp_path / "mesh001.obj", V_cut, F_cut)
    out = mesh(str(tmp_path / "mesh001.obj"))
    np.testing.assert_array_equal(out["F"], F)
    assert out["area"] == pytest.approx(4 * np.pi, rel=0.02)


def test_boundary_loops_are_reported():
    V, F = sphere(400)
    ring = np.flatnonzero(V[F].mean(1)[:, 2] > 0.9)  # cut a cap: one hole
    _, records = repair_mesh(V, np.delete(F, ring, axis=0), "open.obj")
    boundary = _kinds(records)["boundary"]
    assert boundary["count"] == 1 and boundary["level"] == "note"


def test_non_manifold_fin_is_reported_not_rejected():
    V = np.vstack([TET_V, [[0, -1, 0.5]]])
    F = np.vstack([TET_F, [[0, 1, 4]]])
    F2, records = repair_mesh(V, F, "fin.obj")
    assert len(F2) == 5
    assert _kinds(records)["non_manifold_edges"]["level"] == "warning"


def test_fins_are_dropped_from_the_correspondence_mesh_and_reported(tmp_path):
    """Triangles standing on edges of a sphere (each edge then has three faces): kept and warned about by default,
    dropped with a repair record when the largest component is kept (the intrinsic methods' mesh)."""
    from shapecorr.correspondence import mesh

    V, F = sphere(300)
    V2, F2 = with_fins(V, F, 5)
    kept, records = repair_mesh(V2, F2, "fins.obj", keep_largest_component=True)
    np.testing.assert_array_equal(kept, F)
    kinds = _kinds(records)
    assert kinds["non_manifold_pieces"]["count"] == 5 and kinds["non_manifold_pieces"]["level"] == "repair"
    assert "fins.obj: dropped 5 faces joined to the surface only along non-manifold edges" in \
        kinds["non_manifold_pieces"]["message"]
    assert "non_manifold_edges" not in kinds
    same, records = repair_mesh(V2, F2, "fins.obj")
    assert len(same) == len(F2) and "non_manifold_pieces" not in _kinds(records)
    save_obj(tmp_path / "mesh001.obj", V2, F2)
    np.testing.assert_array_equal(mesh(str(tmp_path / "mesh001.obj"))["F"], F)


@pytest.mark.parametrize("V, F, message", [
    (np.vstack([TET_V, [[np.nan, 0, 0]]]), np.vstack([TET_F, [[0, 1, 4]]]), "NaN or infinite"),
    (TET_V, np.array([[0, 0, 1], [1, 2, 2]]), "no valid face left"),
    (np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), np.array([[0, 1, 2]]), "no valid face left"),
    (TET_V, np.zeros((0, 3), dtype=int), "no faces"),
])
def test_unusable_meshes_raise_naming_the_file(V, F, message):
    with pytest.raises(MeshError, match=message) as info:
        repair_mesh(V, F, "bad.obj")
    assert "bad.obj" in str(info.value)


def test_load_repaired_mesh_reads_and_repairs(tmp_path):
    V, F = sphere(200)
    save_obj(tmp_path / "m.obj", V, np.vstack([F, F[0]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # loading itself does not warn: the caller decides
        V2, F2, records = load_repaired_mesh(tmp_path / "m.obj")
    assert len(V2) == len(V)
    np.testing.assert_array_equal(F2, F)
    assert records[0].kind == "duplicate_faces" and str(tmp_path / "m.obj") in records[0].message


def test_vertex_ids_survive_junk_vertices_before_and_among_the_real_ones():
    """Unused vertices placed first and in the middle (as exporters that keep deleted vertices do): the repaired
    faces still index the file's vertices, so a step that compacts or renumbers vertices fails here (the other
    tests append junk after the real vertices, where a compaction changes no id)."""
    V, F = sphere(300)
    order = np.concatenate([[len(V)], np.arange(150), [len(V) + 1], np.arange(150, len(V)), [len(V) + 2]])
    V_junk = np.vstack([V, [[50.0, 0, 0], [0, 60.0, 0], [1e30, 0, 0]]])[order]       # junk at 0, 151 and last
    new_id = np.empty(len(order), dtype=np.int64)
    new_id[order] = np.arange(len(order))
    F_file = np.vstack([new_id[F], new_id[F[3]]])                                    # + one duplicated face
    repaired, records = repair_mesh(V_junk, F_file, "junk.obj", keep_largest_component=True)
    np.testing.assert_array_equal(repaired, new_id[F])
    np.testing.assert_array_equal(V_junk[repaired], V[F])                             # same positions per corner
    assert _kinds(records)["unreferenced_vertices"]["count"] == 3


@pytest.mark.parametrize("far", [1e30, -1e13])
def test_a_used_vertex_out_of_range_is_named(far):
    """A face using a vertex at 1e30 is an error naming the vertex, not "no valid face left after removing
    degenerate and zero-area faces" (a bounding box that dwarfs every face)."""
    V = TET_V.copy()
    V[2, 1] = far
    with pytest.raises(MeshError, match=r"ball\.obj: vertex 2 \(0-based: vertex number 3 of the file\) is out of "
                                        r"range") as err:
        repair_mesh(V, TET_F, "ball.obj")
    assert "no valid face" not in str(err.value)


def test_an_unused_vertex_far_out_is_still_ignored():
    V = np.vstack([TET_V, [[1e30, 0.0, 0.0]]])
    F2, records = repair_mesh(V, TET_F, "ball.obj")
    assert len(F2) == 4 and "unreferenced_vertices" in _kinds(records)


def test_the_correspondence_stage_names_the_file_of_a_vertex_out_of_range(tmp_path):
    from shapecorr.correspondence import mesh

    V, F = sphere(200)
    V = V.copy()
    V[17] = [1e30, 0.0, 0.0]
    path = tmp_path / "scans" / "body_03.obj"
    path.parent.mkdir()
    save_obj(path, V, F)
    with pytest.raises(MeshError) as err:
        mesh(str(path), item_name="body_03")
    assert str(path) in str(err.value) and "vertex 17" in str(err.value) and "out of range" in str(err.value)
