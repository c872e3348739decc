"""A command's dask client: none for --workers 0 (tasks run in this process), started once, on first use."""
from __future__ import annotations

from stages.session import client_session, given_client, stderr_log


def test_workers_zero_runs_in_process_without_a_client(tmp_path):
    with client_session(0, None, str(tmp_path)) as get:
        assert get() is None and get() is None
    assert not (tmp_path / "tmp").exists()              # no dask worker space either


def test_a_given_client_is_used_as_is_and_quiet_logs_nothing(capsys):
    sentinel = object()
    with given_client(lambda: sentinel) as get:
        assert get() is sentinel
    stderr_log(True)("not shown")
    stderr_log(False)("shown")
    assert capsys.readouterr().err == "shown\n"


def test_a_cluster_started_early_is_the_one_get_returns_and_its_log_comes_through_get(tmp_path):
    """``start_early`` starts the local cluster in a thread; the first ``get()`` waits for it and returns that
    client (the same on every call), printing the dashboard line then, from the caller's thread; its workers
    ran the preload (``stages.worker_boot``: Ctrl-C ignored, the stage library imported)."""
    import signal
    import threading

    lines: list[tuple[str, bool]] = []

    def log(*args, **kwargs):
        lines.append((" ".join(map(str, args)), threading.current_thread() is threading.main_thread()))

    with client_session(2, None, str(tmp_path), log) as get:
        get.start_early()
        assert lines == []                                 # nothing printed from the starting thread
        client = get()
        assert get() is client
        assert len(client.nthreads()) == 2
        assert [main for _, main in lines] == [True] and lines[0][0].startswith("dask dashboard: ")
        seen = client.run(lambda: (signal.getsignal(signal.SIGINT) == signal.SIG_IGN,
                                   __import__("stages.registry", fromlist=["_LOADED"])._LOADED))
        assert list(seen.values()) == [(True, True)] * 2


def test_an_error_starting_the_cluster_early_is_raised_by_get_in_the_callers_thread(tmp_path):
    import pytest

    from stages.errors import UserError

    with client_session(1, "not-an-address", str(tmp_path)) as get:
        get.start_early()
        with pytest.raises(UserError, match="not an address"):
            get()
