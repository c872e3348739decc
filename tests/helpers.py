"""Helpers to build small synthetic pipelines for engine tests."""
from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# the BLAS thread variables as they were before tests/conftest.py set one thread (JSON {variable: value or null})
BLAS_ENVIRON_BEFORE = "TESTS_BLAS_ENVIRON_BEFORE"
COURSE_DATA = ROOT.parent / "shared" / "data" / "hw3"
SYNTHETIC_PLUGIN = "tests.stages.synthetic_plugin"   # the test-only stage functions (synthetic.*)


def plugins_env(*modules: str) -> dict[str, str]:
    """Environment for a ``python -m stages`` subprocess that loads the synthetic test plugin and ``modules``
    (the STAGES_PLUGINS development hook), with this checkout importable."""
    return {"STAGES_PLUGINS": ",".join((SYNTHETIC_PLUGIN, *modules)),
            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}

SYNTHETIC_YAML = """\
name: syn
params:
  sigma: 1.0
  root: data
  work: 0
datasets:
  items: {files: "${root}/*.txt"}
stages:
  feat:
    function: synthetic.features
    foreach: items
    inputs: {path: items}
    params: {work: "${work}"}
  dist:
    function: synthetic.pair_distances
    pairs: feat
    tile: 4
  summary:
    function: synthetic.summarize
    inputs: {distances: dist}
    params: {sigma: "${sigma}"}
    metrics: true
  rep:
    function: synthetic.report
    inputs: {summary: summary}
"""


def make_project(tmp: Path, n: int = 12, yaml_text: str = SYNTHETIC_YAML) -> Path:
    """Write ``n`` item files under tmp/data and the pipeline tmp/p.yaml; returns the pipeline path."""
    (tmp / "data").mkdir(parents=True, exist_ok=True)
    for i in range(n):
        (tmp / "data" / f"s{i:03d}.txt").write_text(f"item {i} content {i * 7919 % 1000}\n")
    p = tmp / "p.yaml"
    p.write_text(yaml_text)
    return p


def cli(args: list[str], cwd: Path, env: dict | None = None, timeout: float = 300, **kw) -> subprocess.CompletedProcess:
    """Run ``python -m stages ARGS`` in ``cwd`` with the synthetic test plugin loaded; ``env`` overrides
    (e.g. ``{"STAGES_PLUGINS": ""}`` for what production sees)."""
    full_env = {**os.environ, **plugins_env(), **(env or {})}
    return subprocess.run([sys.executable, "-m", "stages", *args], cwd=cwd, env=full_env, capture_output=True,
                          text=True, timeout=timeout, **kw)


def _fresh_process_state() -> None:
    """Forget what the engine keeps per process, as a new ``python -m stages`` process starts without it: the
    warnings said once, the code digests and the table of them read from a cache, validated manifests, decoded
    entries. (The parsed source files stay: they are keyed by file, size and mtime.)"""
    from stages import errors, fingerprint, read_cache, store

    errors._WARNED.clear()
    fingerprint._MEMO.clear()
    fingerprint._DISK.update(path=None, table={}, dirty=False)
    store._MANIFESTS.clear()
    read_cache.READ_CACHE.items.clear()
    read_cache.READ_CACHE.bytes = 0


def cli_main(args: list[str], cwd: Path, env: dict | None = None, timeout: float | None = None,
             **kw) -> subprocess.CompletedProcess:
    """``python -m stages ARGS`` run by the CLI's ``main`` in this process, as a new process would run it: in
    ``cwd``, with ``env`` added to the environment, the engine's per-process state reset, Python warnings shown
    as in a fresh interpreter, stdout and stderr captured, an uncaught exception printed as a traceback with exit
    code 1, ``SystemExit`` (argparse) turned into its exit code. It saves the 2-4 s each subprocess pays for
    importing dask, Open3D and the plugins.

    For commands that plan, read, or compute with ``--workers 0``, where a test checks exit codes, messages and
    files: not for process behaviour (a kill, Ctrl-C, dask workers), for code edited between two runs (the
    modules are imported once here), or for plugins (``STAGES_PLUGINS``) this process has not loaded. Those
    use :func:`cli` (a real subprocess); ``tests/stages/test_cli_in_process.py`` checks that both give the same
    output.
    ``timeout`` is accepted for symmetry with :func:`cli` (pytest-timeout bounds the test)."""
    import io
    import traceback
    import warnings

    from stages import cli as stages_cli
    from stages import logs

    env = {k: v for k, v in (env or {}).items() if k != "PYTHONPATH"}   # the modules are imported already
    if "STAGES_PLUGINS" in env:
        wanted, loaded = (set(filter(None, x.split(","))) for x in (env["STAGES_PLUGINS"],
                                                                    os.environ.get("STAGES_PLUGINS", "")))
        if not (wanted >= loaded and all(m.partition(":")[0] in sys.modules for m in wanted)):
            raise ValueError("cli_main runs with the plugins this process loaded: use cli() for other plugins")
    if "COLUMNS" not in env and "COLUMNS" not in os.environ:
        env["COLUMNS"] = "80"   # what a process whose output is a pipe sees (shutil.get_terminal_size)
    saved_env = {k: os.environ.get(k) for k in env}
    saved_cwd = os.getcwd()
    root = logging.getLogger()
    saved_handlers, saved_level = root.handlers[:], root.level
    saved_capture, saved_format = logging._warnings_showwarning, warnings.formatwarning
    out, err = io.StringIO(), io.StringIO()
    _fresh_process_state()
    try:
        os.environ.update(env)
        os.chdir(cwd)
        # the engine's reporter is installed anew, writing to this call's stderr
        root.handlers = [h for h in root.handlers if not isinstance(h.formatter, logs._OneLine)]
        logging._warnings_showwarning = None
        with warnings.catch_warnings(), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            warnings.resetwarnings()            # the filters of a new interpreter (pytest records warnings)
            for category in (ResourceWarning, ImportWarning, PendingDeprecationWarning, DeprecationWarning):
                warnings.simplefilter("ignore", category)
            warnings.filterwarnings("default", category=DeprecationWarning, module="__main__")
            try:
                code = stages_cli.main([str(a) for a in args])
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
                if isinstance(exc.code, str):
                    print(exc.code, file=sys.stderr)
            except BaseException:               # noqa: BLE001 - what the interpreter would print
                traceback.print_exc()
                code = 1
            finally:
                logging.captureWarnings(False)
    finally:
        root.handlers, root.level = saved_handlers, saved_level
        logging._warnings_showwarning, warnings.formatwarning = saved_capture, saved_format
        os.chdir(saved_cwd)
        for k, v in saved_env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return subprocess.CompletedProcess([sys.executable, "-m", "stages", *map(str, args)], code, out.getvalue(),
                                       err.getvalue())


def _sigint_default() -> None:
    """In the child: Ctrl-C handled as in a terminal. A test run started in the background by a non-interactive
    shell (``cmd &``, nohup) inherits SIGINT ignored, and Python then never raises KeyboardInterrupt."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def interrupted_run(project: Path, cwd: Path, delay_s: float = 0.0, exit_timeout_s: float = 120,
                    start_timeout_s: float = 240) -> tuple[int, float, str]:
    """``python -m stages run PROJECT --set work=2000 --workers 2`` (the synthetic pipeline) in a new process group,
    SIGINT to the group (a terminal's Ctrl-C) ``delay_s`` after its first ``done`` progress line (the workers up and
    busy). Returns (exit code, seconds from the SIGINT to the exit, stderr). A run that prints no progress line
    within ``start_timeout_s`` or does not exit within ``exit_timeout_s`` is killed (exit code -1 or -9, the
    reason at the end of stderr)."""
    proc = subprocess.Popen([sys.executable, "-m", "stages", "run", str(project), "--set", "work=2000",
                             "--workers", "2"], cwd=cwd, env={**os.environ, **plugins_env()},
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=_sigint_default)
    lines: list[str] = []
    started = threading.Event()

    def read() -> None:
        for line in proc.stderr:
            lines.append(line)
            if "done" in line:
                started.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    if not started.wait(start_timeout_s):
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        return -1, float("nan"), "".join(lines) + f"\n(no progress line within {start_timeout_s:g} s)"
    time.sleep(delay_s)
    t0 = time.perf_counter()
    os.killpg(proc.pid, signal.SIGINT)
    try:
        proc.wait(timeout=exit_timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        lines.append(f"\n(no exit within {exit_timeout_s:g} s of the SIGINT: killed)")
    seconds = time.perf_counter() - t0
    reader.join(timeout=30)
    return proc.returncode, seconds, "".join(lines)


def executed(summary: dict) -> dict[str, int]:
    return {name: s["executed"] for name, s in summary["stages"].items()}


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free right now."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ExternalCluster:
    """A real dask.distributed cluster as separate processes on 127.0.0.1: a scheduler and ``n_workers``
    single-threaded workers. Use as a context manager; ``.address`` is the scheduler address."""

    def __init__(self, workdir: Path, n_workers: int = 2):
        self.workdir, self.n_workers = Path(workdir), n_workers
        self.port = free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> "ExternalCluster":
        import time

        quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
        self.procs.append(subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", str(self.port),
             "--dashboard-address", ":0", "--no-show"], env=self.env, cwd=self.workdir, **quiet))
        for i in range(self.n_workers):
            self.procs.append(subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_worker", self.address, "--nthreads", "1",
                 "--nworkers", "1", "--local-directory", str(self.workdir / f"w{i}"), "--name", f"w{i}",
                 "--no-dashboard"], env=self.env, cwd=self.workdir, **quiet))
        from distributed import Client

        deadline = time.time() + 90
        while True:  # the scheduler needs a moment to listen
            try:
                with Client(self.address, timeout="5s") as c:
                    c.wait_for_workers(self.n_workers, timeout=60)
                return self
            except OSError:
                if time.time() > deadline:
                    self.__exit__(None, None, None)
                    raise
                time.sleep(0.5)

    def __exit__(self, *exc) -> None:
        for p in self.procs[::-1]:
            p.terminate()
        for p in self.procs:
            p.wait(timeout=30)


def sphere(n=1500, seed=0):
    """Unit sphere: Fibonacci points + convex hull, faces oriented outward. V: (n,3), F: (m,3)."""
    import numpy as np
    from scipy.spatial import ConvexHull

    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    V = np.c_[np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)]
    F = ConvexHull(V).simplices
    nrm = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    flip = np.einsum("ij,ij->i", nrm, V[F].mean(1)) < 0
    F[flip] = F[flip][:, ::-1]
    return V, F


def planted_pair_costs(N=12, V=8, D=20, noise=0.2, seed=0):
    """Pair costs C (N,N,V) float32 of noisy copies of one random shape rotated by planted offsets (N,) int
    (shape i's views rolled by offsets[i]): the alignment solvers should recover the offsets up to one shift."""
    import numpy as np

    from corr_core.alignment.pair_costs import pair_costs

    rng = np.random.default_rng(seed)
    base = rng.normal(size=(V, D))
    offsets = rng.integers(0, V, size=N)
    F = np.stack([np.roll(base + noise * rng.normal(size=(V, D)), o, axis=0) for o in offsets])
    return pair_costs(F), offsets


def normalized_distances(X):
    """(k,k) Euclidean distances between the rows of X: (k,d), divided by the largest one."""
    import numpy as np

    D = np.linalg.norm(X[:, None] - X[None], axis=2)
    return D / D.max()


@contextlib.contextmanager
def loaded_plugin(folder: Path, monkeypatch, name: str, source: str):
    """Write the plugin module ``name`` (its ``source``) into ``folder``, import it on the path and load it
    through the registry; unload the module afterwards."""
    from stages import registry

    (Path(folder) / f"{name}.py").write_text(source)
    monkeypatch.syspath_prepend(str(folder))
    sys.modules.pop(name, None)
    registry.load_plugin(name)
    try:
        yield
    finally:
        sys.modules.pop(name, None)


def run_quiet(path, **kw):
    """``stages.api.run`` of the pipeline file ``path`` in this process (no dask), quietly."""
    from stages import api

    return api.run(str(path), workers=0, quiet=True, **kw)


@contextlib.contextmanager
def logged(name: str = "corr_core.geometry.repair"):
    """The messages the ``name`` logger emits inside the block (warnings and above)."""
    messages: list[str] = []
    handler = logging.Handler(logging.WARNING)
    handler.emit = lambda record: messages.append(record.getMessage())
    logger = logging.getLogger(name)
    logger.addHandler(handler)
    try:
        yield messages
    finally:
        logger.removeHandler(handler)


def machine_blas_environ(mp) -> None:
    """Put back, through ``mp`` (a ``pytest.MonkeyPatch``), the BLAS thread variables found before
    tests/conftest.py set one thread: a process started then gets the machine's threads, or the engine's."""
    for var, value in json.loads(os.environ[BLAS_ENVIRON_BEFORE]).items():
        if value is None:
            mp.delenv(var, raising=False)
        else:
            mp.setenv(var, value)
