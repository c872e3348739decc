"""stages/store.py: what the local store loads to read and write an entry."""
from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

from tests.helpers import ROOT

# Puts and reads back one entry in a fresh interpreter, then prints whether zarr got imported.
_PUT_GET = textwrap.dedent("""
    import sys
    import numpy as np
    from stages.store import Store
    store = Store(sys.argv[1])
    value = {"mean_error": 0.01, "per_mesh": {"a": [1, 2]}} if sys.argv[2] == "plain" else {"x": np.arange(5.0)}
    store.put("0" * 32, value)
    got = Store(sys.argv[1]).get("0" * 32)
    assert got["mean_error"] == 0.01 if sys.argv[2] == "plain" else np.array_equal(got["x"], np.arange(5.0))
    print("zarr" in sys.modules)
""")


def _zarr_loaded(tmp_path: Path, kind: str) -> bool:
    out = subprocess.run([sys.executable, "-c", _PUT_GET, str(tmp_path / kind), kind], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip() == "True"


def test_an_entry_without_arrays_is_written_and_read_without_importing_zarr(tmp_path):
    """The run's last step reads the metrics (dicts, no arrays) in the command's own process, and ``results``
    does nothing else: neither pays zarr's import. An entry with arrays still goes through zarr."""
    assert not _zarr_loaded(tmp_path, "plain")
    assert _zarr_loaded(tmp_path, "arrays")
