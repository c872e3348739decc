"""Library messages a user should see reach stderr through the engine's reporter (``stages.errors
.configure_logging``) as one line each: a mesh repair (a ``logging`` warning) and a Python warning, without the
source line Python prints under a warning, the counts in the right number."""
from __future__ import annotations

import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent("""
    import warnings
    import numpy as np
    from corr_core.geometry.repair import repair_mesh, warn_repairs
    from stages.logs import configure_logging

    configure_logging()
    configure_logging()                       # idempotent: still one line per message
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [5, 5, 5]], float)
    F = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3], [1, 2, 3]])
    warn_repairs(repair_mesh(V, F, "008.obj")[1])
    warnings.warn("a library says\\nsomething", UserWarning)
    import logging
    logging.getLogger("distributed.nanny").warning("Worker process still alive after 4.0 seconds, killing")
""")


def test_repairs_and_warnings_are_one_line_log_messages():
    res = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    lines = res.stderr.splitlines()
    assert lines[0].startswith("warning: 008.obj: dropped 1 duplicate face (")      # singular
    assert "warning: 008.obj: flipped 2 faces to a consistent orientation" in lines  # plural
    assert any(x.startswith("warning: 008.obj: 1 vertex used by no face is ignored (first: vertex 4)") for x in lines)
    assert lines[-1] == "warning: a library says something (UserWarning)"
    assert all(x.startswith("warning: ") for x in lines) and len(lines) == len(set(lines))
    assert "Worker process" not in res.stderr            # the libraries underneath: not the user's business
    assert "warn_repairs(" not in res.stderr and ".py:" not in res.stderr   # no source line, no file:line


WORKER_SCRIPT = textwrap.dedent("""
    from distributed import Client, LocalCluster
    from stages.worker import _in_dask_worker

    def task():
        import numpy as np
        from stages.logs import configure_logging
        from stages.worker import _in_dask_worker
        from corr_core.geometry.repair import repair_mesh, warn_repairs
        if _in_dask_worker():                  # as run_task does
            configure_logging()
        V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
        F = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 3, 2], [1, 2, 3]])
        warn_repairs(repair_mesh(V, F, "008.obj")[1])

    if __name__ == "__main__":
        assert not _in_dask_worker()           # the caller's process is left alone
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as c, \\
                Client(c) as client:
            client.submit(task).result()
""")


def test_a_dask_worker_reports_repairs_as_one_line(tmp_path):
    script = tmp_path / "worker_log.py"
    script.write_text(WORKER_SCRIPT)
    res = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=180, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    lines = res.stderr.splitlines()
    assert any(x.startswith("warning: 008.obj: dropped 1 duplicate face (") for x in lines), res.stderr
    assert "warn_repairs(" not in res.stderr and "UserWarning" not in res.stderr, res.stderr
