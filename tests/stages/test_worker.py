"""The worker: input specs load into values, and run_task reports every outcome as a TaskResult."""
from __future__ import annotations

import os

import numpy as np
import pytest

from stages.inputs import DictInput, EntryInput, PairsInput, StackInput, ValueInput
from stages.store import Store
from stages.worker import TaskCall, TaskResult, TaskStatus, load_inputs, run_task


@pytest.fixture
def store(tmp_path):
    return Store(str(tmp_path / "cache"))


def test_input_specs_load_and_name_their_dependencies(store):
    store.put("k1", np.arange(3.0))
    store.put("k2", np.arange(3.0) + 10)
    d = DictInput({"a": EntryInput("k1"), "b": ValueInput("/x.txt", "d")})
    assert d.deps() == ["k1"]
    loaded = d.load(store)
    np.testing.assert_array_equal(loaded["a"], [0, 1, 2])
    assert loaded["b"] == "/x.txt"
    s = StackInput((EntryInput("k1"), EntryInput("k2")))
    assert s.load(store).shape == (2, 3) and s.deps() == ["k1", "k2"]
    assert d.key() == {"a": "k1", "b": "d"} and s.key() == ["k1", "k2"]


def test_pairs_input_assembles_the_full_matrix_with_the_mirror(store):
    # 3 items in blocks [0,2) and [2,3): tiles (0,0), (0,1), (1,1) of a pair function without a mirror
    names = ("a", "b", "c")
    full = np.arange(9.0).reshape(3, 3)
    full = full + full.T
    store.put("t00", full[0:2, 0:2])
    store.put("t01", full[0:2, 2:3])
    store.put("t11", full[2:3, 2:3])
    spec = PairsInput(names, ((0, 2), (2, 3)), ((0, 0, "t00"), (0, 1, "t01"), (1, 1, "t11")), "synthetic.summarize")
    out = spec.load(store)
    assert out["names"] == ["a", "b", "c"]
    np.testing.assert_array_equal(out["matrix"], full)   # the lower tile is the transposed upper one
    assert spec.deps() == ["t00", "t01", "t11"]


def test_items_whose_upstream_task_failed_are_left_out_of_collections(store):
    """A dict or stack input over items loads the items whose task succeeded; the failed item's entry does not
    exist, and the function sees the others only (a stack keeping none is None)."""
    store.put("k1", np.arange(3.0))
    store.put("k3", np.arange(3.0) + 20)
    ok1, ok3 = (TaskResult(k, "feat", n, TaskStatus.OK) for k, n in (("k1", "s1"), ("k3", "s3")))
    failed = TaskResult("k2", "feat", "s2", TaskStatus.FAILED, error="ValueError: bad item")
    inputs = {"d": DictInput({n: EntryInput(k) for n, k in (("s1", "k1"), ("s2", "k2"), ("s3", "k3"))}),
              "s": StackInput((EntryInput("k1"), EntryInput("k2"), EntryInput("k3"))),
              "none": StackInput((EntryInput("k2"),))}
    out = load_inputs(store, inputs, (ok1, failed, ok3))
    assert sorted(out["d"]) == ["s1", "s3"]
    np.testing.assert_array_equal(out["s"], [[0.0, 1.0, 2.0], [20.0, 21.0, 22.0]])
    assert out["none"] is None


def call(store, function="synthetic.scale", inputs=None, params=None, key="out1"):
    return TaskCall(key, "st", "item1", function, params or {"factor": 2.0},
                    inputs if inputs is not None else {"features": ValueInput([1.0, 2.0], "d")}, "item1",
                    store.root, "st[item1]")


def test_ok_then_cached(store):
    res = run_task(call(store))
    assert res.status is TaskStatus.OK and res.status.succeeded
    np.testing.assert_array_equal(store.get("out1"), [2.0, 4.0])
    assert store.manifest("out1")["info"]["stage"] == "st"
    assert run_task(call(store)).status is TaskStatus.CACHED


def test_failure_is_reported_not_raised(store):
    res = run_task(call(store, params={"factor": "x"}))
    assert res.status is TaskStatus.FAILED and not res.status.succeeded
    assert res.error.startswith("ValueError:") and "Traceback" in res.traceback
    assert not store.has("out1")


def test_dependents_of_a_failed_task_are_skipped(store):
    failed = TaskResult("up", "feat", "s1", TaskStatus.FAILED, display="feat[s1]")
    res = run_task(call(store), failed)
    assert res.status is TaskStatus.SKIPPED and res.because == "feat[s1]"
    assert not store.has("out1")


def test_a_corrupt_input_entry_is_named(store):
    store.put("up", np.arange(4.0))
    arrays = os.path.join(store.object_path("up"))
    chunk = next(os.path.join(d, f) for d, _, fs in os.walk(arrays) for f in fs if "zarr.json" not in f)
    with open(chunk, "r+b") as fh:
        data = bytearray(fh.read())
        data[len(data) // 2] ^= 0xFF
        fh.seek(0)
        fh.write(bytes(data))
    res = run_task(call(store, inputs={"features": EntryInput("up")}))
    assert res.status is TaskStatus.CORRUPT and res.corrupt_key == "up"
