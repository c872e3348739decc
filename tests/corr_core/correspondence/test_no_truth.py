"""A test mesh whose vertex count differs from the template's has no landmark ground truth: it is left out of
the accuracies with a warning saying why, instead of averaging a meaningless 0.0 in."""
import numpy as np
import pytest

from corr_core.correspondence.measures import identity_truth_problem, scorable_results


def test_identity_truth_problem():
    assert identity_truth_problem(100, 100) is None
    assert identity_truth_problem(None, 80) is None
    assert "80 vertices vs the template's 100" in identity_truth_problem(100, 80)


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
    descriptor = {"mesh001": _mark_truth(right, 500, 500), "mesh002": _mark_truth(wrong, 500, 480)}
    assert "no_truth" in descriptor["mesh002"] and "no_truth" not in descriptor["mesh001"]
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    with pytest.warns(UserWarning, match=r"mesh002: 480 vertices vs the template's 500.*no ground truth"):
        out = evaluate(str(tmp_path / "lm.txt"), str(tmp_path / "sparse.txt"), descriptor=descriptor,
                       out_dir=str(out_dir))
    assert out["accuracy"]["descriptor"] == 1.0
    assert list(out["accuracy_per_mesh"]["descriptor"]) == ["mesh001"]
    assert "mesh002" in out["not_scored"]
