"""A test mesh whose triangles are not the template's has no landmark ground truth from the shared landmark file
(whatever its vertex count): it is left out of the accuracies with a warning saying why, instead of averaging a
meaningless 0.0 in. A mesh with the template's triangles and unused vertices appended keeps it."""
import numpy as np
import pytest

from corr_core.correspondence.measures import numbering_problem, scorable_results
from corr_core.geometry.primitives import triangles_key

F = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]])    # a fan of 4 triangles, 5 vertices


def test_numbering_problem_compares_triangles_not_counts():
    assert numbering_problem(F, F[[2, 0, 3, 1]][:, [1, 2, 0]]) is None      # faces reordered, rotated: same
    perm = np.array([2, 0, 3, 1, 4])                                        # same counts, vertices shuffled
    assert "same counts, another vertex order" in numbering_problem(F, perm[F], 5, 5)
    assert "5 vertices / 4 faces vs the template's 6 / 4" in numbering_problem(F, F + 1, 6, 5)
    assert numbering_problem(F, F, 5, 7) is None                            # 2 unused vertices appended
    assert triangles_key(F) == triangles_key(F[::-1]) != triangles_key(perm[F])


def test_scorable_results_split():
    results = {"mesh001": {"all": [0]}, "mesh002": {"all": [0], "no_truth": "why"}}
    scorable, skipped = scorable_results(results)
    assert list(scorable) == ["mesh001"] and skipped == {"mesh002": "why"}


def test_evaluate_leaves_out_meshes_without_truth(tmp_path):
    from shapecorr.correspondence import _mark_truth, evaluate

    (tmp_path / "lm.txt").write_text("1,A\n2,B\n3,C\n4,D\n")
    (tmp_path / "sparse.txt").write_text("1,A\n3,C\n4,D\n")
    right = {"all": np.arange(4), "sparse": np.arange(3)}
    wrong = {"all": np.array([1, 0, 3, 2]), "sparse": np.array([1, 0, 2])}
    template = {"triangles": triangles_key(F), "n_faces": 4, "n_vertices": 500}
    appended = {**template, "n_vertices": 502, "landmark_source": "shared"}          # unused vertices appended
    shuffled = {"triangles": triangles_key(np.array([2, 0, 3, 1, 4])[F]), "n_faces": 4, "n_vertices": 500}
    descriptor = {"mesh001": _mark_truth(right, template, appended), "mesh002": _mark_truth(wrong, template, shuffled),
                  "mesh003": _mark_truth(right, template, {**shuffled, "landmark_source": "own"})}
    assert "no_truth" in descriptor["mesh002"] and "no_truth" not in descriptor["mesh001"]
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    with pytest.warns(UserWarning, match=r"mesh002: its triangles are not the template's \(500 vertices / 4 faces vs the template's 500 / 4: "
                                           r"same counts, another vertex order\).*not scored"):
        out = evaluate(str(tmp_path / "lm.txt"), str(tmp_path / "sparse.txt"), descriptor=descriptor,
                       out_dir=str(out_dir))
    assert out["accuracy"]["descriptor"] == 1.0
    assert list(out["accuracy_per_mesh"]["descriptor"]) == ["mesh001", "mesh003"]
    assert "mesh002" in out["not_scored"]
