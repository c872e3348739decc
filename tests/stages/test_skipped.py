"""An item a stage function returns as ``Skipped(why)``: stored like any result, printed and counted by ``run``,
received as ``Skipped`` downstream, and not recomputed by the next run."""
from __future__ import annotations

import pytest

from stages import api
from stages.codec import decode, encode
from stages.skipped import Skipped

from tests.helpers import executed, make_project

SKIP_YAML = """\
name: skip
datasets:
  items: {files: "data/*.txt"}
stages:
  lengths:
    function: synthetic.maybe_skip
    foreach: items
    inputs: {path: items}
    params: {skip_on: "content 7"}
  counted:
    function: synthetic.count_skipped
    inputs: {items: lengths}
    metrics: true
"""


def test_skipped_is_stored_and_read_back_inside_any_value():
    arrays: dict = {}
    value = {"a": Skipped("mesh002 has no landmarks"), "b": [1, Skipped("x")]}
    assert decode(encode(value, arrays), arrays) == value and arrays == {}
    assert decode(encode({"skipped": "a plain dict"}, arrays), arrays) == {"skipped": "a plain dict"}
    with pytest.raises(ValueError, match="needs a reason"):
        Skipped("  ")


def test_run_reports_each_skipped_item_and_downstream_receives_it(tmp_path, monkeypatch, dask_client, capfd):
    monkeypatch.chdir(tmp_path)
    path = make_project(tmp_path, n=6, yaml_text=SKIP_YAML)
    # item i holds "content {i * 7919 % 1000}": s003 -> 757, s005 -> 595 ... pick the ones holding "content 7"
    marked = sorted(p.stem for p in (tmp_path / "data").glob("*.txt") if "content 7" in p.read_text())
    assert marked, "the synthetic items changed: pick another marker"
    summary = api.run(str(path), client_getter=lambda: dask_client, quiet=False)
    assert summary["stages"]["lengths"]["items_skipped"] == len(marked)
    assert [(s["stage"], s["item"]) for s in summary["items_skipped"]] == [("lengths", m) for m in marked]
    err = capfd.readouterr().err
    for m in marked:
        assert f"lengths[{m}]: skipped: {m}.txt contains 'content 7'" in err
    assert api.result(str(path), "lengths", marked[0]) == Skipped(f"{marked[0]}.txt contains 'content 7'")
    counted = api.result(str(path), "counted")
    assert counted["skipped"] == {m: f"{m}.txt contains 'content 7'" for m in marked}
    assert counted["kept"] == 6 - len(marked)
    again = api.run(str(path), client_getter=lambda: dask_client, quiet=True)
    assert executed(again) == {"lengths": 0, "counted": 0} and again["items_skipped"] == []
