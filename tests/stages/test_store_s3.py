"""The cache on object storage (``--cache s3://bucket/prefix``) against a real S3-compatible server.

The server is moto in server mode (a real HTTP endpoint on 127.0.0.1, started here), reached through s3fs and
zarr's fsspec store exactly as an AWS or MinIO endpoint would be (``AWS_ENDPOINT_URL``). Skipped, with the
reason, when the ``s3`` / ``test`` extras (s3fs, moto[server]) are not installed.
"""
from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import threading
import uuid
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("s3fs", reason="s3fs is not installed (pip install -e '.[s3,test]')")
pytest.importorskip("moto.server", reason="moto is not installed (pip install -e '.[test]')")
pytest.importorskip("flask", reason="moto's server mode needs flask (pip install 'moto[server]')")

from stages import api  # noqa: E402
from stages.errors import CorruptEntry, UserError  # noqa: E402
from stages.cache import open_store  # noqa: E402

from tests.helpers import SYNTHETIC_YAML, executed, free_port, make_project, plugins_env, run_quiet  # noqa: E402

S3_ENV = {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing", "AWS_DEFAULT_REGION": "us-east-1"}


@pytest.fixture(scope="module")
def s3_endpoint():
    """A moto S3 server on a free port for this module; the AWS_* variables point every client at it."""
    import logging

    from moto.server import ThreadedMotoServer

    logging.getLogger("werkzeug").setLevel(logging.ERROR)  # no line per request

    port = free_port()
    server = ThreadedMotoServer(ip_address="127.0.0.1", port=port, verbose=False)
    env = {**S3_ENV, "AWS_ENDPOINT_URL": f"http://127.0.0.1:{port}"}
    saved = {k: os.environ.get(k) for k in env}
    with _atomic_conditional_puts():
        server.start()
        os.environ.update(env)
        yield env
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        server.stop()


@contextlib.contextmanager
def _atomic_conditional_puts():
    """moto answers a create-only PUT (``If-None-Match: *``) by looking for the object, then storing it, without
    a lock: two such PUTs of one key at the same moment can both succeed (seen under load), where S3 lets one
    through. Here they are served one at a time, as S3 would decide them."""
    from moto.moto_server.werkzeug_app import DomainDispatcherApplication

    lock = threading.Lock()
    serve = DomainDispatcherApplication.__call__

    def one_create_at_a_time(self, environ, start_response):
        if environ.get("REQUEST_METHOD") == "PUT" and environ.get("HTTP_IF_NONE_MATCH"):
            with lock:  # the handler stores the object before it returns
                return serve(self, environ, start_response)
        return serve(self, environ, start_response)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(DomainDispatcherApplication, "__call__", one_create_at_a_time)
        yield


@pytest.fixture()
def s3fs_client(s3_endpoint):
    import fsspec
    return fsspec.filesystem("s3", use_listings_cache=False)


@pytest.fixture()
def bucket(s3fs_client):
    name = "b" + uuid.uuid4().hex[:12]
    s3fs_client.mkdir(name)
    return name


@pytest.fixture()
def project(tmp_path, monkeypatch, bucket):
    """The synthetic pipeline in tmp_path with its cache at s3://BUCKET/cache (local part under tmp_path)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("STAGES_LOCAL_CACHE", str(tmp_path / "local"))
    p = make_project(tmp_path, n=8)
    return p, f"s3://{bucket}/cache"


def _feat_key(path, cache) -> str:
    plan = api.plan_pipeline(str(path), cache_dir=cache, quiet=True)
    return plan.stages["feat"].tasks[0].key


def test_run_noop_and_param_change_on_s3(project, tmp_path, s3fs_client, s3_endpoint):
    """A cold run on a dask worker process, then in this process: a no-op, and a changed parameter."""
    path, cache = project
    proc = _cli(["run", str(path), "--cache", cache, "--workers", "1", "--quiet", "--summary-json", "s.json"],
                tmp_path, s3_endpoint, str(tmp_path / "local"))
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    first = json.loads((tmp_path / "s.json").read_text())
    assert all(n > 0 for n in executed(first).values())
    assert s3fs_client.isfile(f"{cache}/.stages-cache")
    assert s3fs_client.find(f"{cache}/manifest"), "the entries are on the object store"
    assert not os.path.exists(tmp_path / "local" / "s3" / cache[5:] / "manifest")  # ... not in the local part
    local = run_quiet(path, cache_dir=str(tmp_path / "local-cache"), output_dir=str(tmp_path / "out-local"))
    assert executed(local) == executed(first)
    s3_plan = api.plan_pipeline(str(path), cache_dir=cache, quiet=True)
    local_plan = api.plan_pipeline(str(path), cache_dir=str(tmp_path / "local-cache"), quiet=True)
    assert [t.key for t in s3_plan.tasks()] == [t.key for t in local_plan.tasks()]  # the same cache keys
    assert api.metrics(s3_plan) == api.metrics(local_plan)

    assert set(executed(run_quiet(path, cache_dir=cache)).values()) == {0}  # no-op: nothing computed
    changed = executed(run_quiet(path, cache_dir=cache, overrides=["sigma=2.0"]))
    assert changed == {"feat": 0, "dist": 0, "summary": 1, "rep": 1}
    assert (tmp_path / "results" / "syn" / "rep" / "summary.txt").read_text().startswith("synthetic: 8 items")


def test_a_noop_run_asks_the_store_about_each_task_once(project, monkeypatch):
    """A no-op run on an object store looks each task's result up once (its manifest and one listing of its
    data): not once to decide whether to start workers and again to list what runs, nor again for its
    ``left_out``. Each look-up is requests to the server, per task, on every run."""
    from collections import Counter

    from stages.object_store import ObjectStore

    path, cache = project
    run_quiet(path, cache_dir=cache)
    asked: Counter = Counter()
    manifest = ObjectStore.manifest

    def counted(self, key):
        asked[key] += 1
        return manifest(self, key)
    monkeypatch.setattr(ObjectStore, "manifest", counted)
    assert set(executed(run_quiet(path, cache_dir=cache)).values()) == {0}
    plan = api.plan_pipeline(str(path), cache_dir=cache, quiet=True)
    assert set(asked) == {t.key for t in plan.tasks()}
    per_item = {t.key: name for name, sp in plan.stages.items() if len(sp.tasks) > 1 for t in sp.tasks}
    assert {"feat", "dist"} <= set(per_item.values())
    assert {per_item[k]: n for k, n in asked.items() if k in per_item and n != 1} == {}
    # the summary and the report are also read for the metrics and to publish their files
    assert all(n <= 4 for n in asked.values()), asked


DAMAGES = ("deleted", "truncated", "edited", "array-gone")


def test_unusable_entries_are_recomputed_with_a_warning(project, s3fs_client, capsys):
    """Four per-item entries, each damaged another way: each is missing for status and recomputed by the next
    run, with a warning naming the manifest when one is there but unusable; nothing else runs again."""
    path, cache = project
    run_quiet(path, cache_dir=cache)
    tasks = api.plan_pipeline(str(path), cache_dir=cache, quiet=True).stages["feat"].tasks[:len(DAMAGES)]
    manifests = {}
    for damage, task in zip(DAMAGES, tasks):
        key = task.key
        manifest = manifests[damage] = f"{cache}/manifest/{key[:2]}/{key}.json"
        text = s3fs_client.cat_file(manifest).decode()
        if damage == "deleted":
            s3fs_client.rm_file(manifest)
        elif damage == "truncated":
            s3fs_client.pipe_file(manifest, text[: len(text) // 2].encode())
        elif damage == "edited":  # valid JSON, one inline value changed: the manifest's checksum catches it
            s3fs_client.pipe_file(manifest, text.replace('"feat"', '"fake"').encode())
        else:
            writer = json.loads(text)["location"]
            s3fs_client.rm_file(f"{cache}/objects/{key[:2]}/{key}/{writer}/a0.zarr/zarr.json")
    capsys.readouterr()
    assert {r["stage"]: r["to_run"] for r in api.status(str(path), cache_dir=cache)}["feat"] == len(DAMAGES)
    summary = run_quiet(path, cache_dir=cache)
    assert executed(summary) == {"feat": len(DAMAGES), "dist": 0, "summary": 0, "rep": 0}  # same content
    err = capsys.readouterr().err
    for damage in DAMAGES[1:]:
        assert f"cache entry {manifests[damage]}" in err, damage
    store = open_store(cache)
    assert all(store.has(t.key) for t in tasks)


def test_a_changed_array_fails_its_checksum(project, s3fs_client):
    path, cache = project
    run_quiet(path, cache_dir=cache)
    key = _feat_key(path, cache)
    store = open_store(cache)
    good = store.get(key)
    writer = store.manifest(key)["location"]
    from stages.read_cache import READ_CACHE as _READ_CACHE
    import zarr
    arr = zarr.open_array(store=store._zarr_store(f"{store.object_path(key)}/{writer}/a0.zarr", read_only=False),
                          mode="r+", zarr_format=3)
    arr[0, 0] = arr[0, 0] + 1  # a valid chunk with other content
    _READ_CACHE.drop(key)
    with pytest.raises(CorruptEntry, match="checksum"):
        store.get(key)
    arr[0, 0] = good[0, 0]  # the original content again: it verifies
    _READ_CACHE.drop(key)
    np.testing.assert_array_equal(store.get(key), good)


def test_two_writers_of_one_entry_store_it_once(s3_endpoint, bucket, s3fs_client, tmp_path, monkeypatch):
    """Both writers have written their data before either writes its manifest: the first manifest wins, the
    other writer keeps it and deletes its own data; the entry is complete and reads back the value."""
    monkeypatch.setenv("STAGES_LOCAL_CACHE", str(tmp_path / "local"))
    from stages.object_store import ObjectStore

    cache, key = f"s3://{bucket}/c", "ab" + "0" * 30
    both_written = threading.Barrier(2)
    commit = ObjectStore._commit

    def commit_after_both(self, k, manifest):
        both_written.wait(timeout=30)
        return commit(self, k, manifest)

    monkeypatch.setattr(ObjectStore, "_commit", commit_after_both)
    value = {"x": np.arange(12.0).reshape(3, 4), "n": 3}
    stored = []
    threads = [threading.Thread(target=lambda: stored.append(open_store(cache).put(key, value))) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert len(stored) == 2 and stored[0]["location"] == stored[1]["location"]  # both report the same entry
    writers = s3fs_client.ls(f"{cache}/objects/ab/{key}", detail=False)
    assert [w.rsplit("/", 1)[-1] for w in writers] == [stored[0]["location"]]  # the loser's data is gone
    store = open_store(cache)
    assert store.has(key)
    got = store.get(key)
    np.testing.assert_array_equal(got["x"], value["x"])
    assert got["n"] == 3


def test_a_create_stored_but_answered_late_keeps_its_data(s3_endpoint, bucket, tmp_path, monkeypatch):
    """The manifest's create-only PUT is stored, but its answer is lost: the client's retry is refused (the
    manifest is there: this writer's own). The writer keeps its data, and the entry is complete. The same when
    the answer never comes (the put fails): the manifest may name the data, so the data stays (for gc)."""
    monkeypatch.setenv("STAGES_LOCAL_CACHE", str(tmp_path / "local"))
    from stages.object_store import ObjectStore

    create = ObjectStore._create
    refusal: list[BaseException] = []

    def stored_then_refused(self, path, data):
        create(self, path, data)
        if "/manifest/" in path:
            raise refusal[0]

    monkeypatch.setattr(ObjectStore, "_create", stored_then_refused)
    value = {"x": np.arange(6.0), "n": 2}
    for i, error in enumerate([FileExistsError("the retry: At least one of the pre-conditions did not hold"),
                               UserError("cannot write the cache: the endpoint does not answer")]):
        refusal[:] = [error]
        store, key = open_store(f"s3://{bucket}/c"), f"ef{i}" + "2" * 29
        if isinstance(error, FileExistsError):
            assert store.put(key, value)["location"] == store.manifest(key)["location"]
        else:
            with pytest.raises(UserError):
                store.put(key, value)
        assert store.has(key), error
        np.testing.assert_array_equal(store.get(key)["x"], value["x"])


def test_a_result_with_other_content_replaces_the_stored_one(s3_endpoint, bucket, tmp_path, monkeypatch):
    """A result stored without some failed items is replaced when they are retried and it is computed again
    (same key, other content); a second write of the same content keeps the first copy."""
    monkeypatch.setenv("STAGES_LOCAL_CACHE", str(tmp_path / "local"))
    store, key = open_store(f"s3://{bucket}/c"), "cd" + "1" * 30
    partial = store.put(key, {"x": np.zeros(2)}, info={"left_out": [["k", "feat", "s001", "failed"]]})
    assert store.put(key, {"x": np.zeros(2)}, info={"left_out": [["k", "feat", "s001", "failed"]]})["location"] \
        == partial["location"]
    full = store.put(key, {"x": np.ones(3)}, info={"left_out": []})
    assert full["location"] != partial["location"] and store.left_out(key) == []
    np.testing.assert_array_equal(store.get(key)["x"], np.ones(3))


RACE_YAML = SYNTHETIC_YAML.replace("""  dist:
    function: synthetic.pair_distances
    pairs: feat""", """  met:
    function: race.meet
    foreach: feat
    inputs: {features: feat}
    params: {folder: "${meet_folder}"}
  dist:
    function: synthetic.pair_distances
    pairs: met""").replace("  work: 0\n", "  work: 0\n  meet_folder: meet\n")


def _cli(args: list[str], cwd, endpoint_env: dict, local: str) -> subprocess.Popen:
    env = {**os.environ, **plugins_env("tests.stages.race_plugin"), **endpoint_env, "STAGES_LOCAL_CACHE": local}
    return subprocess.Popen([sys.executable, "-m", "stages", *args], cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _writers(fs, store, key: str) -> list[str]:
    try:
        return fs.ls(store.object_path(key), detail=False)
    except FileNotFoundError:  # an entry without arrays or files is its manifest alone
        return []


def test_two_concurrent_runs_into_one_bucket(tmp_path, bucket, s3_endpoint, s3fs_client, monkeypatch):
    """Two runs, as if on two machines (each its own local folder), compute every entry of stage ``met`` at
    the same moment (race.meet waits for both) and store it into one bucket: both succeed, each entry is kept
    once, complete, and both give identical results."""
    monkeypatch.chdir(tmp_path)
    path = make_project(tmp_path, n=6, yaml_text=RACE_YAML)
    cache = f"s3://{bucket}/cache"
    procs = [_cli(["run", str(path), "--cache", cache, "--quiet", "--workers", "0", "--out", str(tmp_path / f"out{i}"),
                   "--summary-json", str(tmp_path / f"s{i}.json")], tmp_path, s3_endpoint, str(tmp_path / f"local{i}"))
             for i in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (_, err) in zip(procs, outs):
        assert p.returncode == 0, err
    runs = [json.loads((tmp_path / f"s{i}.json").read_text())["stages"] for i in range(2)]
    assert [r["met"]["executed"] for r in runs] == [6, 6]  # both computed (and tried to store) every entry
    m0, m1 = (json.loads((tmp_path / f"out{i}" / "metrics.json").read_text()) for i in range(2))
    assert m0 == m1
    assert ((tmp_path / "out0" / "rep" / "summary.txt").read_bytes()
            == (tmp_path / "out1" / "rep" / "summary.txt").read_bytes())
    from stages import registry
    registry.load_plugin("tests.stages.race_plugin")  # to plan it here too
    store = open_store(cache)
    plan = api.plan_pipeline(str(path), cache_dir=cache, quiet=True)
    for t in plan.tasks():  # every entry complete, and exactly one writer's data kept for it
        assert store.has(t.key)
        store.get(t.key)
        assert len(_writers(s3fs_client, store, t.key)) <= 1
    for t in plan.stages["met"].tasks:
        assert [w.rsplit("/", 1)[-1] for w in _writers(s3fs_client, store, t.key)] == [store.manifest(t.key)["location"]]


def test_gc_on_s3(project, tmp_path, s3fs_client, monkeypatch):
    import stages.object_store as object_store

    path, cache = project
    run_quiet(path, cache_dir=cache)
    run_quiet(path, cache_dir=cache, overrides=["sigma=2.0"])      # two more entries (summary, rep)
    store = open_store(cache)
    key = _feat_key(path, cache)
    old_writer = store.manifest(key)["location"]
    store.invalidate(key)
    run_quiet(path, cache_dir=cache)                                 # recomputed: the old data is stale now
    foreign = f"{cache}/objects/notes.txt"
    s3fs_client.pipe_file(foreign, b"mine")                          # not the engine's: never removed
    n_before = len(store.all_keys())

    dry = api.gc([str(path)], cache, dry=True)
    assert dry["removed"] == 2 and len(store.all_keys()) == n_before  # a dry run removes nothing
    monkeypatch.setattr(object_store, "STALE_WRITE_S", 0.0)
    res = api.gc([str(path)], cache)
    assert res["removed"] == 2 and res["kept"] == n_before - 2 and res["bytes_freed"] > 0
    assert not s3fs_client.exists(f"{store.object_path(key)}/{old_writer}")
    assert s3fs_client.exists(f"{store.object_path(key)}/{store.manifest(key)['location']}")
    assert s3fs_client.cat_file(foreign) == b"mine"
    assert set(executed(run_quiet(path, cache_dir=cache)).values()) == {0}  # what is reachable is kept

    s3fs_client.rm_file(f"{cache}/.stages-cache")
    with pytest.raises(UserError, match="marker"):
        api.gc([str(path)], cache)
    assert len(store.all_keys()) == n_before - 2


def test_a_prefix_with_other_content_is_refused(project, bucket, s3fs_client):
    path, _ = project
    s3fs_client.pipe_file(f"{bucket}/holiday.jpg", b"not a cache")
    with pytest.raises(UserError, match="not a stages cache"):
        run_quiet(path, cache_dir=f"s3://{bucket}")
    assert s3fs_client.ls(bucket, detail=False) == [f"{bucket}/holiday.jpg"]  # nothing written there


@pytest.mark.parametrize("name", ["runs_2023.csv", "manifesto.txt", "objects-old"])
def test_a_prefix_with_names_that_merely_start_like_the_engines_is_refused(project, bucket, s3fs_client, name):
    path, _ = project
    s3fs_client.pipe_file(f"{bucket}/{name}", b"not a cache")
    with pytest.raises(UserError, match="not a stages cache") as err:
        run_quiet(path, cache_dir=f"s3://{bucket}")
    assert name in str(err.value)
    assert s3fs_client.ls(bucket, detail=False) == [f"{bucket}/{name}"]  # nothing written there


def test_a_missing_bucket_or_backend_is_a_clear_error(project, monkeypatch):
    path, _ = project
    with pytest.raises(UserError, match="does not exist"):
        run_quiet(path, cache_dir="s3://no-such-bucket-" + uuid.uuid4().hex[:8] + "/c")
    import fsspec

    def no_backend(protocol, **kw):
        raise ImportError("Install s3fs to access S3")

    monkeypatch.setattr(fsspec, "filesystem", no_backend)
    with pytest.raises(UserError) as err:
        api.status(str(path), cache_dir="s3://x/c")
    assert "s3fs" in str(err.value) and ".[s3]" in err.value.fix


def test_the_report_names_the_cache_url_and_its_local_folder(project, tmp_path):
    """The report's run details show the cache as given (the s3:// URL), and the local folder beside it."""
    import re

    from stages.report import write_report

    path, cache = project
    run_quiet(path, cache_dir=cache)
    html = Path(write_report(str(path), cache_dir=cache)).read_text()
    rows = dict(re.findall(r"<tr><td>(cache[^<]*)</td><td>([^<]*)</td></tr>", html))
    assert rows == {"cache": cache, "cache local folder": open_store(cache).root}
    assert str(tmp_path / "local") in rows["cache local folder"]


# --- a store that does not answer, or refuses the client, is an error line, never a traceback ---

def _no_retries(env: dict) -> dict:
    """botocore retries a refused connection for ~20 s by default: once is enough here."""
    return {**env, "AWS_MAX_ATTEMPTS": "1", "AWS_RETRY_MODE": "standard"}


def test_an_unreachable_endpoint_is_an_error_line_naming_it(project, tmp_path, s3_endpoint):
    path, cache = project
    dead = f"http://127.0.0.1:{free_port()}"
    for cmd in (["run", str(path), "--workers", "0"], ["status", str(path)], ["gc", str(path)]):
        proc = _cli([*cmd, "--cache", cache], tmp_path, _no_retries({**s3_endpoint, "AWS_ENDPOINT_URL": dead}),
                    str(tmp_path / "local"))
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 1, (cmd, err)
        assert "Traceback" not in err and f"error: cannot read the cache {cache}" in err, (cmd, err)
        assert f"the endpoint {dead} does not answer" in err and "fix: check that the server is running" in err


def test_missing_credentials_are_an_error_line_saying_what_to_set(project, tmp_path, s3_endpoint):
    path, cache = project
    env = {**os.environ, **plugins_env(), "STAGES_LOCAL_CACHE": str(tmp_path / "local"), "HOME": str(tmp_path),
           "AWS_ENDPOINT_URL": s3_endpoint["AWS_ENDPOINT_URL"], "AWS_EC2_METADATA_DISABLED": "true",
           "AWS_SHARED_CREDENTIALS_FILE": str(tmp_path / "none"), "AWS_CONFIG_FILE": str(tmp_path / "none")}
    for k in ("AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY", "AWS_SESSION_TOKEN", "AWS_PROFILE"):
        env.pop(k, None)
    r = subprocess.run([sys.executable, "-m", "stages", "run", str(path), "--workers", "0", "--cache", cache],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert f"error: cannot read the cache {cache} (endpoint {s3_endpoint['AWS_ENDPOINT_URL']}): no usable " \
           "credentials" in r.stderr, r.stderr
    assert "AWS_ACCESS_KEY_ID" in r.stderr


@pytest.mark.e2e   # a whole multi-process run: .ci/run (pytest -m e2e), not the README's test command
def test_a_server_killed_mid_run_keeps_what_was_stored(tmp_path, monkeypatch):
    """The S3 server stops while a run stores per-item results: the run ends with an error line naming the
    endpoint (no traceback); once the server is back, every entry stored before is there and complete, and the
    next run computes only the rest."""
    import time

    from moto.server import ThreadedMotoServer

    port = free_port()
    endpoint = f"http://127.0.0.1:{port}"
    env = _no_retries({**S3_ENV, "AWS_ENDPOINT_URL": endpoint})
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("STAGES_LOCAL_CACHE", str(tmp_path / "local"))
    server = ThreadedMotoServer(ip_address="127.0.0.1", port=port, verbose=False)
    server.start()
    try:
        import fsspec
        fs = fsspec.filesystem("s3", use_listings_cache=False)
        bucket = "k" + uuid.uuid4().hex[:12]
        fs.mkdir(bucket)
        cache = f"s3://{bucket}/cache"
        path = make_project(tmp_path, n=12)
        proc = _cli(["run", str(path), "--cache", cache, "--workers", "0", "--set", "work=400"], tmp_path, env,
                    str(tmp_path / "local"))
        deadline = time.time() + 120
        while time.time() < deadline and len(fs.find(f"{cache}/manifest")) < 3:
            time.sleep(0.2)
        server.stop()                                    # mid-run: 3 or more of the 12 items stored
        _, err = proc.communicate(timeout=180)
        assert proc.returncode == 1, err
        assert "Traceback" not in err and f"the endpoint {endpoint} does not answer" in err, err
    finally:
        server = ThreadedMotoServer(ip_address="127.0.0.1", port=port, verbose=False)  # back, with its data
        server.start()
    try:
        plan = api.plan_pipeline(str(path), ["work=400"], cache_dir=cache, quiet=True)
        stored = [t for t in plan.stages["feat"].tasks if plan.store.has(t.key)]
        assert 3 <= len(stored) < 12
        for t in stored:
            plan.store.get(t.key)                        # complete and checksummed
        s = run_quiet(path, cache_dir=cache, overrides=["work=400"])
        assert executed(s)["feat"] == 12 - len(stored)
    finally:
        server.stop()
