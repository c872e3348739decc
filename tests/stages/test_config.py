"""Bad pipeline files and overrides give clear errors naming the file, key/line and a fix."""
from __future__ import annotations

import pytest

from stages.config import load_pipeline
from stages.errors import PipelineError
from stages.plan import build_plan

from tests.helpers import SYNTHETIC_YAML, cli_main, make_project

CASES = {
    "unknown_function": (SYNTHETIC_YAML.replace("synthetic.summarize", "synthetic.summarise"),
                         ["stages.summary.function", "unknown function 'synthetic.summarise'", "synthetic.summarize"]),
    "unknown_param": (SYNTHETIC_YAML.replace('params: {sigma: "${sigma}"}', "params: {sigmaa: 1}"),
                      ["stages.summary.params", "unknown parameter 'sigmaa'", "sigma"]),
    "unknown_stage_ref": (SYNTHETIC_YAML.replace("inputs: {distances: dist}", "inputs: {distances: distt}"),
                          ["stages.summary.inputs.distances", "unknown dataset or stage 'distt'", "dist"]),
    "unknown_dataset": (SYNTHETIC_YAML.replace("foreach: items", "foreach: itemz"),
                        ["stages.feat.foreach", "unknown dataset or stage 'itemz'", "items"]),
    "wrong_type": (SYNTHETIC_YAML.replace('params: {sigma: "${sigma}"}', "params: {sigma: [1, 2]}"),
                   ["stages.summary.params.sigma", "wrong type", "float"]),
    "unknown_reference": (SYNTHETIC_YAML.replace("${sigma}", "${sigmaa}"),
                          ["stages.summary.params", "unknown parameter reference '${sigmaa}'", "sigma"]),
    "unknown_top_key": (SYNTHETIC_YAML + "stagez: {}\n", ["stagez", "unknown top-level key", "stages"]),
    "unknown_stage_key": (SYNTHETIC_YAML.replace("    tile: 4", "    tiles: 4"), ["stages.dist.tiles", "tile"]),
    "unwired_input": (SYNTHETIC_YAML.replace("    inputs: {path: items}\n", ""),
                      ["stages.feat.inputs", "input 'path'", "not wired"]),
    "fanout_mismatch": (SYNTHETIC_YAML.replace("    pairs: feat\n", "    foreach: feat\n"),
                        ["stages.dist", "runs per pair", "pairs:"]),
    "yaml_syntax": (SYNTHETIC_YAML.replace("  sigma: 1.0", "  sigma: [1.0"), ["invalid YAML"]),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_pipeline_files_name_file_key_and_fix(tmp_path, case, monkeypatch):
    monkeypatch.chdir(tmp_path)
    text, needles = CASES[case]
    path = make_project(tmp_path, n=3, yaml_text=text)
    with pytest.raises(PipelineError) as info:
        build_plan(load_pipeline(str(path)))
    msg = str(info.value)
    assert str(path.name) in msg
    for needle in needles:
        assert needle in msg, (needle, msg)
    if case not in ("yaml_syntax",):
        assert info.value.line is not None and f"p.yaml:{info.value.line}:" in msg


def test_cycle_is_reported_with_its_path(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    text = SYNTHETIC_YAML + """  a:
    function: synthetic.scale
    foreach: b
    inputs: {features: b}
  b:
    function: synthetic.scale
    foreach: a
    inputs: {features: a}
"""
    path = make_project(tmp_path, n=3, yaml_text=text)
    with pytest.raises(PipelineError, match=r"cycle: (a -> b -> a|b -> a -> b)"):
        load_pipeline(str(path))


def test_missing_data_folder_names_dataset_and_fix(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = make_project(tmp_path, n=3)
    with pytest.raises(PipelineError) as info:
        build_plan(load_pipeline(str(path), ["root=nowhere"]))
    msg = str(info.value)
    assert "datasets.items.files" in msg and "nowhere" in msg and "--set data.root" in msg


def test_empty_folder_is_an_error(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = make_project(tmp_path, n=3)
    (tmp_path / "empty").mkdir()
    with pytest.raises(PipelineError, match="no files match"):
        build_plan(load_pipeline(str(path), ["root=empty"]))


@pytest.mark.parametrize("override,needle", [
    ("sigmaa=2", "unknown parameter 'sigmaa'"),
    ("summary.sigmaa=2", "stage 'summary' has no parameter 'sigmaa'"),
    ("sigma", "not key=value"),
])
def test_bad_overrides(tmp_path, monkeypatch, override, needle):
    monkeypatch.chdir(tmp_path)
    path = make_project(tmp_path, n=3)
    with pytest.raises(PipelineError, match=needle):
        load_pipeline(str(path), [override])


def test_overrides_reach_the_stage_parameters(tmp_path, monkeypatch):
    """``STAGE.PARAM=v`` sets that stage's parameter (over its ${...} value), ``KEY=v`` a ``params`` key that
    stages read through ${KEY}; an int given for a float parameter is stored as a float (same cache key)."""
    monkeypatch.chdir(tmp_path)
    path = make_project(tmp_path, n=3)
    pipe = load_pipeline(str(path), ["summary.sigma=0.25", "feat.dim=8"])
    assert pipe.stages["summary"].params["sigma"] == 0.25 and pipe.stages["feat"].params["dim"] == 8
    pipe = load_pipeline(str(path), ["sigma=2"])
    assert pipe.params["sigma"] == 2 and pipe.stages["summary"].params["sigma"] == 2.0
    assert type(pipe.stages["summary"].params["sigma"]) is float


def test_missing_pipeline_file_via_cli_exits_2(tmp_path):
    res = cli_main(["run", "nope.yaml"], cwd=tmp_path)
    assert res.returncode == 2 and "nope.yaml" in res.stderr and "not found" in res.stderr
    assert "Traceback" not in res.stderr


def test_every_command_has_help(tmp_path):
    for cmd in ([], ["run"], ["status"], ["sweep"], ["results"], ["gc"], ["report"], ["functions"]):
        res = cli_main([*cmd, "--help"], cwd=tmp_path)
        assert res.returncode == 0 and "usage:" in res.stdout, cmd
