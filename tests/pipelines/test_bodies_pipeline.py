"""pipelines/bodies.yaml (template of one body against poses of other bodies, generated): it plans with other
bodies by default, and its stages are pipeline.yaml's problem-2 stages (so the two do not drift apart).
Running it is measured by hand (the command in its header); its stages are the ones the other pipeline tests run."""
from __future__ import annotations

import yaml

from stages import api

from tests.helpers import ROOT

BODIES = ROOT / "pipelines" / "bodies.yaml"
DEFAULT = ROOT / "pipeline.yaml"


def _yaml(path):
    return yaml.safe_load(path.read_text())


def test_bodies_pipeline_generates_other_bodies_and_plans(tmp_path):
    plan = api.plan_pipeline(str(BODIES), cache_dir=str(tmp_path / "cache"), quiet=True)
    gen = plan.pipeline.generated["bodies"]
    assert gen.generator == "generate.humanoid"
    assert gen.params["vary_bodies"] is True and gen.params["n_poses"] == 6
    same = api.plan_pipeline(str(BODIES), ["bodies.vary=false", "bodies.n_poses=3"], cache_dir=str(tmp_path / "cache"),
                             quiet=True).pipeline.generated["bodies"].params
    assert same["vary_bodies"] is False and same["n_poses"] == 3
    assert {"dense_sparse", "dense_auto", "dense_measures", "placed_landmarks", "evaluate"} <= set(plan.stages)
    assert plan.pipeline.stages["evaluate"].metrics


def test_bodies_stages_are_the_default_pipelines_correspondence_stages():
    """Every problem-2 stage of pipeline.yaml, with the same function, inputs and params (the template named
    ${template}, the metrics stage named evaluate as in scape.yaml), but for one difference: the dense maps'
    refinement plan for bodies of other people (docs/dense.md "Refinement plan"). Update pipelines/bodies.yaml
    beside it."""
    default, bodies = _yaml(DEFAULT)["stages"], _yaml(BODIES)["stages"]
    names = list(default)
    corr = names[names.index("mesh"):]
    expected = yaml.safe_load(yaml.safe_dump({("evaluate" if n == "corr_metrics" else n): default[n] for n in corr})
                              .replace("${humans.template}", "${template}"))
    for stage in ("dense_sparse", "dense_auto"):
        assert "refine" not in expected[stage]["params"]
        expected[stage]["params"]["refine"] = "extrinsic+deform"
    assert bodies == expected
    assert _yaml(BODIES)["datasets"] == yaml.safe_load(
        yaml.safe_dump({k: v for k, v in _yaml(DEFAULT)["datasets"].items() if "humans.root" in str(v)})
        .replace("${humans.root}", "${data.root}"))
