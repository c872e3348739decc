"""Results from Python and on the command line: ``api.result`` returns one stage's stored
result for an item; ``results`` prints the headline keys first, then the rest, keys with spaces quoted."""
from __future__ import annotations

import numpy as np
import pytest

from stages import api
from stages.errors import UserError
from stages.headline import headline_first
from stages.results import format_results

from tests.helpers import ROOT, make_project, plugins_env, run_quiet


@pytest.fixture
def synthetic(monkeypatch):
    monkeypatch.setenv("STAGES_PLUGINS", plugins_env()["STAGES_PLUGINS"])


def test_result_returns_the_stored_value_of_one_item(tmp_path, synthetic, monkeypatch):
    monkeypatch.chdir(tmp_path)
    p = make_project(tmp_path)
    cache = str(tmp_path / "cache")
    run_quiet(p, cache_dir=cache)
    plan = api.plan_pipeline(str(p), [], cache_dir=cache)
    (task,) = [t for t in plan.stages["feat"].tasks if t.label == "s003"]
    feat = api.result(str(p), "feat", "s003", cache_dir=cache)
    np.testing.assert_array_equal(feat, plan.store.get(task.key))
    assert not np.array_equal(feat, api.result(str(p), "feat", "s004", cache_dir=cache))
    summary = api.result(str(p), "summary", cache_dir=cache)            # a once stage: no item
    assert summary["n_items"] == 12 and summary["sigma"] == 1.0
    assert api.result(plan, "summary") == summary                        # a Plan works too
    with pytest.raises(UserError, match=r"summary is not computed with these params"):
        api.result(str(p), "summary", params={"sigma": 7}, cache_dir=cache)
    run_quiet(p, cache_dir=cache, overrides=["sigma=7"])
    assert api.result(str(p), "summary", params={"sigma": 7}, cache_dir=cache)["sigma"] == 7.0
    with pytest.raises(UserError, match=r"no stage 'nope'.*\n  fix: use one of: feat, dist, summary, rep"):
        api.result(str(p), "nope", cache_dir=cache)
    with pytest.raises(UserError, match=r"stage 'feat' has no item 's999' \(its items: s000, s001"):
        api.result(str(p), "feat", "s999", cache_dir=cache)
    with pytest.raises(UserError, match=r"stage 'feat' is a per-item stage: name the item"):
        api.result(str(p), "feat", cache_dir=cache)


def test_results_lines_quote_keys_with_spaces():
    text = format_results([("a.b", 0.123456), ("top.Left Toe -> Right Toe", 3), ("c", "x")], n_headline=1)
    quoted = '"top.Left Toe -> Right Toe"'
    assert text.splitlines() == [f"{'a.b':<40} 0.1235", "", f"{quoted:<40} 3", f"{'c':<40} x"]
    assert all(len(line.rsplit(None, 1)) == 2 for line in text.splitlines() if line)


def test_results_print_the_headline_keys_first_in_the_tables_order(tmp_path):
    plan = api.plan_pipeline(str(ROOT / "pipeline.yaml"), [], cache_dir=str(tmp_path / "cache"))
    m = {"labels": [1, 2], "solver": "spectral", "other": {"x": 1.0}, "accuracy": {"mrf": 0.5, "descriptor": 0.25},
         "ground_truth": {"exact": 1.0, "n": 24, "exact_spectral": 1.0, "mean_error_deg": 0.07}}
    pairs, n = headline_first(plan, m)
    keys = [k for k, _ in pairs]
    assert keys[:n] == ["ground_truth.exact_spectral", "ground_truth.mean_error_deg", "accuracy.mrf",
                        "accuracy.descriptor"]
    assert keys[n:] == ["solver", "other.x", "ground_truth.exact", "ground_truth.n"]     # then the rest, in order
