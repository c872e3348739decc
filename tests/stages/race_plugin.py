"""A test-only stage function that makes two runs compute the same entry at the same moment (test_store_s3).

Loaded by the test's CLI subprocesses through ``STAGES_PLUGINS`` next to the synthetic plugin; never in production.
"""
from __future__ import annotations

import hashlib
import os
import time

import numpy as np

from stages.registry import register


@register("race.meet", fanout="item")
def meet(features, *, folder: str, parties: int = 2, timeout_s: float = 90.0) -> np.ndarray:
    """Return ``features`` (any array) doubled, once ``parties`` processes have reached this same item.

    Each caller leaves ``folder/<content hash>.<pid>`` and waits until ``parties`` such files exist (at most
    ``timeout_s`` seconds), so every run has computed the entry before any of them stores it."""
    arr = np.asarray(features)
    tag = hashlib.blake2b(arr.tobytes(), digest_size=8).hexdigest()
    os.makedirs(folder, exist_ok=True)
    open(os.path.join(folder, f"{tag}.{os.getpid()}"), "w").close()
    deadline = time.monotonic() + timeout_s
    while sum(n.startswith(tag + ".") for n in os.listdir(folder)) < parties and time.monotonic() < deadline:
        time.sleep(0.02)
    return arr * 2
