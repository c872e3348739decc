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


class _StuckClient:
    """A dask client whose close times out (dask's event loop stuck), with one local worker process ``proc``."""

    def __init__(self, proc):
        from types import SimpleNamespace

        nanny = SimpleNamespace(process=SimpleNamespace(process=SimpleNamespace(pid=proc.pid)))
        self.cluster = SimpleNamespace(workers={"w0": nanny}, close=self.close)
        self.closes: list[float] = []

    def close(self, timeout=None):
        self.closes.append(timeout)
        raise TimeoutError(f"timed out after {timeout} s.")


def test_a_close_that_times_out_kills_the_local_workers_and_keeps_the_ctrl_c(tmp_path, monkeypatch):
    """A Ctrl-C whose cluster then does not close in time is still a Ctrl-C (exit 130, not "cannot access: timed
    out after 60 s", seen on CI): the worker processes are killed and one warning line says so; a run that ended
    normally is not failed by it either."""
    import subprocess
    import sys
    from contextlib import nullcontext

    import pytest

    import stages.session as session

    for interrupted in (True, False):
        proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
        stuck = _StuckClient(proc)
        monkeypatch.setattr(session, "make_client", lambda *a, **k: stuck)
        lines: list[str] = []
        try:
            with pytest.raises(KeyboardInterrupt) if interrupted else nullcontext():
                with client_session(2, None, str(tmp_path), lambda *a, **k: lines.append(" ".join(a))) as get:
                    assert get() is stuck
                    if interrupted:
                        raise KeyboardInterrupt
            assert proc.wait(timeout=30) == -9                 # killed, not left running
        finally:
            proc.kill()
        assert stuck.closes and all(t <= session.CLOSE_TIMEOUT_S for t in stuck.closes)
        assert len(lines) == 1 and lines[0].startswith("warning: dask did not shut down cleanly"), lines
        assert "1 local worker process(es) killed" in lines[0], lines
