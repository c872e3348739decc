"""The local cluster's worker processes: one BLAS thread each, and no MALLOC_TRIM_THRESHOLD_ (dask's default
makes numpy-heavy tasks 2-3x slower in a worker: stages.execute.WORKER_ENVIRON), and no dask profiler (1.1-1.2x:
stages.execute.worker_profile_config)."""
from __future__ import annotations

import os


def _worker_environment() -> dict:
    return {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}


def test_local_workers_run_with_one_blas_thread_and_glibcs_own_malloc_thresholds(dask_client):
    seen = dask_client.run(_worker_environment)
    assert len(seen) == 2
    for env in seen.values():
        assert env == {"MALLOC_TRIM_THRESHOLD_": None, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}


def _profiler_on() -> bool:
    import dask
    return bool(dask.config.get("distributed.worker.profile.enabled"))


def test_local_workers_run_without_dasks_profiler(dask_client):
    assert list(dask_client.run(_profiler_on).values()) == [False, False]


def test_the_profiler_variable_given_by_the_user_is_left_to_dask(monkeypatch):
    from stages.execute import WORKER_PROFILE_ENV, worker_profile_config

    monkeypatch.delenv(WORKER_PROFILE_ENV, raising=False)
    assert worker_profile_config() == {"distributed.worker.profile.enabled": False}
    monkeypatch.setenv(WORKER_PROFILE_ENV, "True")
    assert worker_profile_config() == {}


# ---- the order tasks are handed to the workers ------------------------------------------------------
from stages import api  # noqa: E402
from stages.execute import dispatch_order  # noqa: E402
from stages.plan import Task  # noqa: E402
from tests.helpers import make_project  # noqa: E402

# Two chains over the same items: ``short`` (one stage, then a summary) is written first; ``long`` (three
# stages, then a summary) has more tasks still to come after its first stage.
TWO_CHAINS_YAML = """\
name: chains
params: {work: 40}
datasets:
  items: {files: "data/*.txt"}
stages:
  short:
    function: synthetic.features
    foreach: items
    inputs: {path: items}
    params: {work: "${work}", dim: 8}
  short_sum: {function: synthetic.collect, inputs: {items: "short[*]"}}
  long1:
    function: synthetic.features
    foreach: items
    inputs: {path: items}
    params: {work: "${work}", dim: 16}
  long2: {function: synthetic.scale, foreach: items, inputs: {features: long1}, params: {factor: 2.0}}
  long3: {function: synthetic.scale, foreach: items, inputs: {features: long2}, params: {factor: 3.0}}
  long_sum: {function: synthetic.collect, inputs: {items: "long3[*]"}}
"""


def _task(key: str, stage: str, deps: list[str]) -> Task:
    return Task(stage=stage, label=key, key=key, function="f", params={}, inputs={}, deps=deps, input_digests={})


def test_dispatch_order_puts_the_longest_chain_still_to_come_first_ties_in_plan_order():
    tasks = {t.key: t for t in [_task("a", "short", []), _task("b", "long1", []), _task("c", "long2", ["b"]),
                                _task("s", "short_sum", ["a"]), _task("d", "long3", ["c"])]}
    dependents = {"a": ["s"], "b": ["c"], "c": ["d"], "s": [], "d": []}
    order = dispatch_order(tasks, dependents)
    assert sorted(tasks, key=order.get) == ["b", "a", "c", "s", "d"]


def test_a_run_starts_every_task_of_the_longest_chain_before_a_shorter_chain_written_first(tmp_path, dask_client,
                                                                                           monkeypatch):
    """On the 2-worker cluster: every ``long1`` task starts before any ``short`` task (each ~40 ms). Handed to
    dask all at once (the scheduler's order: as submitted, stage by stage) ``short`` would start first."""
    monkeypatch.chdir(tmp_path)
    path = make_project(tmp_path, n=8, yaml_text=TWO_CHAINS_YAML)
    api.run(str(path), cache_dir=str(tmp_path / "cache"), output_dir=str(tmp_path / "out"), quiet=True,
            client_getter=lambda: dask_client)
    plan = api.plan_pipeline(str(path), cache_dir=str(tmp_path / "cache"), output_dir=str(tmp_path / "out"),
                             quiet=True)

    def started(stage: str) -> list[float]:
        manifests = [plan.store.manifest(t.key) for t in plan.stages[stage].tasks]
        return [m["created"] - m["info"]["seconds"] for m in manifests]

    assert len(started("long1")) == len(started("short")) == 8
    assert max(started("long1")) <= min(started("short"))
