"""bench/zoomout_steps.py --compare: two runs' rows side by side (no map is made here)."""
from __future__ import annotations

import json

import pytest


def _row(target, mode, error, seconds, flipped=False, step=4):
    return {"target": target, "mode": mode, "step": step, "mean_error": error, "flipped": flipped,
            "seconds": seconds}


BASE = [_row("a", "sparse", 0.010, 2.0), _row("b", "sparse", 0.020, 2.0), _row("c", "sparse", 0.030, 2.0),
        _row("a", "auto", 0.010, 4.0), _row("b", "auto", 0.050, 4.0, flipped=True)]
OTHER = [_row("a", "sparse", 0.012, 1.0), _row("b", "sparse", 0.015, 1.0), _row("c", "sparse", 0.030, 1.0),
         _row("a", "auto", 0.011, 3.0), _row("b", "auto", 0.020, 3.0), _row("z", "auto", 0.5, 9.0)]


def test_compare_rows_counts_lower_higher_rise_flips_and_the_cpu_ratio():
    from bench.zoomout_steps import compare_rows

    table = compare_rows(BASE, OTHER)
    sparse, auto = table["sparse"], table["auto"]
    assert sparse["targets"] == 3 and (sparse["lower"], sparse["higher"]) == (1, 1)       # c: a tie, neither
    assert sparse["base_mean"] == pytest.approx(0.02) and sparse["other_mean"] == pytest.approx(0.019)
    assert sparse["largest_rise"] == pytest.approx(0.002) and sparse["cpu_ratio"] == pytest.approx(0.5)
    assert auto["targets"] == 2                                                         # "z": only in OTHER
    assert (auto["base_flips"], auto["other_flips"]) == (1, 0) and auto["cpu_ratio"] == pytest.approx(0.75)
    assert auto["base_median"] == pytest.approx(0.03)


def test_compare_refuses_several_steps_and_names_an_unreadable_file(tmp_path, capsys):
    from bench.zoomout_steps import compare_rows, main

    with pytest.raises(ValueError, match="several rows"):
        compare_rows(BASE + [_row("a", "sparse", 0.01, 2.0, step=2)], OTHER)
    with pytest.raises(ValueError, match="share no target"):
        compare_rows(BASE, [_row("q", "auto", 0.1, 1.0)])
    good, bad = tmp_path / "base.json", tmp_path / "bad.json"
    good.write_text(json.dumps({"settings": {"n_patches": 300}, "data": "x", "rows": BASE}))
    bad.write_text("[1, 2]")
    assert main(["--compare", str(good), str(bad)]) == 2
    assert str(bad) in capsys.readouterr().err
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"settings": {"n_patches": 150}, "data": "x", "rows": OTHER}))
    assert main(["--compare", str(good), str(other)]) == 0
    out = capsys.readouterr().out
    assert "1 / 1" in out and "0.500" in out
