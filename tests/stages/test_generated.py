"""A generated dataset's folder follows its generator and parameters: another value, another folder."""
from __future__ import annotations

from stages import api

YAML = """\
name: gen
generated:
  things: {{generator: synthetic.write_items, params: {{n: {n}, seed: {seed}}}}}
datasets:
  items: {{files: "${{generated.things}}/*.txt"}}
stages:
  feat:
    function: synthetic.features
    foreach: items
    inputs: {{path: items}}
"""


def _folder(tmp_path, name: str, **params) -> str:
    path = tmp_path / name
    path.write_text(YAML.format(**params))
    return api.plan_pipeline(str(path), cache_dir=str(tmp_path / "cache"), quiet=True).pipeline.generated["things"].path


def test_the_generated_folder_changes_with_the_parameters_only(tmp_path):
    first = _folder(tmp_path, "a.yaml", n=6, seed=0)
    assert _folder(tmp_path, "b.yaml", n=6, seed=0) == first          # same generator and values: shared
    assert _folder(tmp_path, "c.yaml", n=7, seed=0) != first
    assert _folder(tmp_path, "d.yaml", n=6, seed=1) != first
    assert first.startswith(str(tmp_path / "cache" / "generated"))
