"""``bench/demo.py``'s argument checks (its cold runs are timed by hand, not in the tests)."""
from __future__ import annotations

import subprocess
import sys

from tests.helpers import ROOT


def test_a_work_path_that_is_a_file_is_an_error_naming_it(tmp_path):
    a_file = tmp_path / "notes.txt"
    a_file.write_text("mine\n")
    res = subprocess.run([sys.executable, str(ROOT / "bench" / "demo.py"), "--work", str(a_file)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert f"--work {a_file}: is a file, not a folder" in res.stderr
    assert a_file.read_text() == "mine\n"
