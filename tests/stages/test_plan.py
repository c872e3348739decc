"""Planning: content-defined pair blocks, typed sources and input specs."""
from __future__ import annotations

from stages import api
from stages.inputs import EntryInput, PairsInput, StackInput
from stages.plan import SourceKind, make_blocks

from tests.helpers import make_project


def test_blocks_are_stable_under_insertion():
    names = sorted(f"shape{i:04d}" for i in range(500))
    blocks = make_blocks(names, 32)
    assert blocks[0][0] == 0 and blocks[-1][1] == 500
    sizes = [b - a for a, b in blocks]
    assert max(sizes) <= 64 and len(blocks) >= 500 // 64
    inserted = sorted(names + ["shape0250x"])
    as_sets = lambda nm, bl: {tuple(nm[a:b]) for a, b in bl}  # noqa: E731
    changed = as_sets(inserted, make_blocks(inserted, 32)) ^ as_sets(names, blocks)
    assert len(changed) <= 4  # the block that holds the new item (old and new version), at most one split


def test_sources_and_input_specs_are_typed(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    plan = api.plan_pipeline(str(make_project(tmp_path, n=5)), quiet=True)
    assert plan.datasets["items"].kind is SourceKind.ITEMS
    feat, dist, summary = plan.stages["feat"], plan.stages["dist"], plan.stages["summary"]
    assert feat.source.kind is SourceKind.ITEMS and all(isinstance(v, EntryInput) for v in feat.source.items.values())
    assert isinstance(dist.source.pairs, PairsInput) and dist.source.pairs.names == tuple(sorted(feat.source.items))
    tile = dist.tasks[0]
    assert isinstance(tile.inputs["A"], StackInput) and set(tile.deps) <= {t.key for t in feat.tasks}
    assert summary.tasks[0].inputs["distances"] is dist.source.pairs
    assert summary.tasks[0].deps == sorted(t.key for t in dist.tasks)
