"""The cache cannot be fooled: everything read back is checksummed, and an unusable entry or engine table is
treated as missing (one warning, recomputed in the same run), never a traceback or a wrong value."""
from __future__ import annotations

import glob
import json
import os

import pytest

from stages import api
from stages.store import Store

from tests.helpers import cli_main, executed, make_project, run_quiet

GENERATED_YAML = """\
name: gen
generated:
  things: {generator: synthetic.write_items, params: {n: 6}}
datasets:
  items: {files: "${generated.things}/*.txt"}
stages:
  feat:
    function: synthetic.features
    foreach: items
    inputs: {path: items}
"""


@pytest.fixture()
def project(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return make_project(tmp_path)



def _manifest_of(path, stage: str) -> str:
    """The manifest file of the (once) stage ``stage`` of the pipeline at ``path``."""
    plan = api.plan_pipeline(str(path), quiet=True)
    return plan.store.manifest_path(plan.stages[stage].tasks[0].key)


def _torun_quiet(path) -> dict[str, int]:
    return {r["stage"]: r["to_run"] for r in api.status(str(path))}


def test_an_edited_inline_value_is_detected_and_recomputed(project, capsys):
    run_quiet(project)
    true_value = api.metrics(api.plan_pipeline(str(project), quiet=True))["mean_affinity"]
    path = _manifest_of(project, "summary")
    text = open(path, encoding="utf-8").read()
    digits = repr(true_value)
    assert digits in text
    forged = digits[:-1] + ("1" if digits[-1] != "1" else "2")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text.replace(digits, forged))  # still valid JSON, only one digit changed

    assert _torun_quiet(project)["summary"] == 1                      # status does not say "cached"
    m = api.metrics(api.plan_pipeline(str(project), quiet=True))
    assert m.get("mean_affinity") != float(forged)              # the forged number is never shown
    assert "does not match its checksum" in capsys.readouterr().err
    s = run_quiet(project)
    assert executed(s)["summary"] == 1
    assert api.metrics(api.plan_pipeline(str(project), quiet=True))["mean_affinity"] == true_value


@pytest.mark.parametrize("damage", [b'{"format": 2, "key": "tru', b"\xff\xfe\x00garbage", b"null", b"[]", b"",
                                    b"[" * 200000, b'{"a":' * 5000 + b"1" + b"}" * 5000])
def test_an_unreadable_manifest_counts_as_missing(project, capsys, damage):
    run_quiet(project)
    path = _manifest_of(project, "summary")
    with open(path, "wb") as fh:
        fh.write(damage)
    assert _torun_quiet(project) == {"feat": 0, "dist": 0, "summary": 1, "rep": 0}
    m = api.metrics(api.plan_pipeline(str(project), quiet=True))
    assert m["_not_computed"] == ["summary"]
    s = run_quiet(project)
    assert executed(s) == {"feat": 0, "dist": 0, "summary": 1, "rep": 0}
    err = capsys.readouterr().err
    assert "treating it as missing" in err
    assert "Traceback" not in err


@pytest.mark.parametrize("table", ["filehash.json", "fingerprints.json", "runs"])
def test_unreadable_engine_tables_are_rebuilt(project, tmp_path, table):
    args = ["run", str(project), "--workers", "0", "--summary-json", "s.json"]
    assert cli_main(args, tmp_path).returncode == 0
    root = api.plan_pipeline(str(project), quiet=True).store.root
    paths = glob.glob(os.path.join(root, "runs", "*.json")) if table == "runs" else [os.path.join(root, table)]
    assert paths
    for p in paths:
        with open(p, "wb") as fh:
            fh.write(b"\xff\xfe{truncated")
    r = cli_main(args, tmp_path)
    assert r.returncode == 0 and "warning:" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert sum(executed(json.load(open(tmp_path / "s.json"))).values()) == 0  # the tables are only bookkeeping
    r = cli_main(["status", str(project)], tmp_path)     # rewritten: no warning the second time
    assert r.returncode == 0 and "warning:" not in r.stderr, r.stderr


@pytest.mark.parametrize("table", ["filehash.json", "fingerprints.json", "published"])
def test_deeply_nested_json_in_an_engine_table_is_damage_not_a_traceback(project, tmp_path, table):
    """'[' * 200000 (or JSON nested deep enough that hashing it recurses too far) is read as a damaged file: one
    warning naming it, then rebuilt; never a RecursionError that blocks every command."""
    args = ["run", str(project), "--workers", "0", "--summary-json", "s.json"]
    assert cli_main(args, tmp_path).returncode == 0
    root = api.plan_pipeline(str(project), quiet=True).store.root
    path = (os.path.join(tmp_path, "results", "syn", ".stages-published.json") if table == "published"
            else os.path.join(root, table))
    assert os.path.isfile(path)
    for damage in (b"[" * 200000, b'{"checksum": "x", "data": ' + b"[" * 5000 + b"]" * 5000 + b"}"):
        with open(path, "wb") as fh:
            fh.write(damage)
        r = cli_main(args, tmp_path)
        assert r.returncode == 0 and "Traceback" not in r.stderr and "RecursionError" not in r.stderr, r.stderr
        assert f"warning: {path}" in r.stderr, r.stderr
        assert sum(executed(json.load(open(tmp_path / "s.json"))).values()) == 0
        for cmd in (["status", str(project)], ["results", str(project)]):
            r = cli_main(cmd, tmp_path)
            assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr


def test_a_damaged_array_is_reported_once(project, tmp_path):
    """A changed array chunk: one ``warning:`` line naming the entry, through the engine's reporter (it was also
    printed a second time as a raw UserWarning), and the entry is recomputed."""
    args = ["run", str(project), "--workers", "0", "--summary-json", "s.json"]
    assert cli_main(args, tmp_path).returncode == 0
    plan = api.plan_pipeline(str(project), quiet=True)
    key = plan.stages["dist"].tasks[0].key
    chunks = [p for p in glob.glob(os.path.join(plan.store.object_path(key), "**", "*"), recursive=True)
              if os.path.isfile(p) and not p.endswith("zarr.json")]
    chunk = max(chunks, key=os.path.getsize)
    data = bytearray(open(chunk, "rb").read())
    data[-1] ^= 0xFF                                                   # same size, other content
    open(chunk, "wb").write(bytes(data))
    r = cli_main(args + ["--set", "sigma=2.0"], tmp_path)                  # summary reads the damaged tile
    assert r.returncode == 0, r.stderr
    assert r.stderr.count(f"cache entry {key[:12]} is corrupt") == 1, r.stderr
    assert "UserWarning" not in r.stderr and "warnings.warn" not in r.stderr, r.stderr
    assert executed(json.load(open(tmp_path / "s.json")))["dist"] == 1


def test_a_forged_engine_table_is_not_trusted(project, capsys):
    """A filehash.json row edited to claim an old digest for a changed file is not believed."""
    run_quiet(project)
    root = api.plan_pipeline(str(project), quiet=True).store.root
    doc = json.load(open(os.path.join(root, "filehash.json"), encoding="utf-8"))
    (project.parent / "data" / "s003.txt").write_text("changed content\n")
    table = doc["data"]
    for row in table.values():
        row[1] = 0  # rows no longer match any file's mtime: everything must be hashed again anyway
    with open(os.path.join(root, "filehash.json"), "w", encoding="utf-8") as fh:
        json.dump(doc, fh)
    s = run_quiet(project)
    assert executed(s)["feat"] == 1
    assert "filehash.json does not match its checksum" in capsys.readouterr().err


def test_a_deleted_published_file_is_repaired_in_the_samerun_quiet(project, tmp_path):
    s = run_quiet(project)
    published = s["published"]
    plan = api.plan_pipeline(str(project), quiet=True)
    key = plan.stages["rep"].tasks[0].key
    files_dir = plan.store.files_path(key)
    os.remove(os.path.join(files_dir, "summary.txt"))
    assert _torun_quiet(project)["rep"] == 1
    s = run_quiet(project)
    assert executed(s)["rep"] == 1
    assert s["published"] == published
    assert (tmp_path / "results" / "syn" / "rep" / "summary.txt").is_file()


def test_a_truncated_manifest_of_a_file_stage_does_not_lose_the_outputs(project, tmp_path):
    s = run_quiet(project)
    published = s["published"]
    path = _manifest_of(project, "rep")
    data = open(path, "rb").read()
    with open(path, "wb") as fh:
        fh.write(data[: len(data) // 2])
    s = run_quiet(project)
    assert executed(s)["rep"] == 1
    assert s["published"] == published
    assert (tmp_path / "results" / "syn" / "rep" / "summary.txt").is_file()


def test_a_changed_published_file_of_the_same_size_is_repaired_in_the_samerun_quiet(project, tmp_path):
    run_quiet(project)
    plan = api.plan_pipeline(str(project), quiet=True)
    stored = os.path.join(plan.store.files_path(plan.stages["rep"].tasks[0].key), "summary.txt")
    good = open(stored, encoding="utf-8").read()
    with open(stored, "w", encoding="utf-8") as fh:
        fh.write("X" * len(good))  # same size: only the checksum tells
    s = run_quiet(project)
    assert executed(s)["rep"] == 1
    assert (tmp_path / "results" / "syn" / "rep" / "summary.txt").read_text() == good


def test_has_agrees_with_get_for_a_missing_array(project):
    run_quiet(project)
    plan = api.plan_pipeline(str(project), quiet=True)
    store: Store = plan.store
    key = plan.stages["feat"].tasks[0].key
    import shutil

    shutil.rmtree(store.object_path(key))
    assert not store.has(key)


def test_an_edited_generated_dataset_is_detected_and_regenerated(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    p = tmp_path / "gen.yaml"
    p.write_text(GENERATED_YAML)
    run_quiet(p)
    plan = api.plan_pipeline(str(p), quiet=True)
    folder = plan.pipeline.generated["things"].path
    victim = os.path.join(folder, "item002.txt")
    original = open(victim, encoding="utf-8").read()
    with open(victim, "w", encoding="utf-8") as fh:
        fh.write("edited by hand\n")
    s = run_quiet(p)
    assert "generated dataset 'things'" in capsys.readouterr().err
    assert open(victim, encoding="utf-8").read() == original
    assert sum(executed(s).values()) == 0  # regenerated identically: every result is still valid
    os.remove(victim)
    run_quiet(p)
    assert open(victim, encoding="utf-8").read() == original


def test_an_array_that_cannot_be_written_fails_the_put_and_stores_no_entry(tmp_path, monkeypatch):
    """The arrays of an entry are written together (stages.codec.write_arrays); one that fails must fail the
    put, as it did written alone: no manifest may claim data that is not there."""
    import numpy as np
    import zarr

    store = Store(str(tmp_path / "cache"))
    store.claim()
    local_store = zarr.storage.LocalStore
    monkeypatch.setattr(zarr.storage, "LocalStore", lambda path, **kw: local_store(path, read_only=True))
    with pytest.raises(ValueError, match="read-only"):
        store.put("0" * 32, {"a": np.zeros(3), "b": np.ones(2)}, info={})
    monkeypatch.undo()
    assert not store.has("0" * 32)
