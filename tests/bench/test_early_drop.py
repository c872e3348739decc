"""``bench/early_drop.py``'s argument checks (its maps are timed by hand, not in the tests)."""
from __future__ import annotations

import subprocess
import sys

from tests.helpers import ROOT


def test_a_pair_count_below_one_is_an_error_naming_it():
    res = subprocess.run([sys.executable, str(ROOT / "bench" / "early_drop.py"), "--pairs", "0"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert "--pairs must be >= 1, got 0" in res.stderr
