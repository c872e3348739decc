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
