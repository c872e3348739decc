"""The per-process cache of decoded entries (``READ_CACHE``), bounded in bytes."""
from __future__ import annotations

import os
from collections import OrderedDict
from typing import Any


class ReadCache:
    """Per-process cache of decoded entries (content-addressed, so never stale), bounded in bytes.

    Pair tiles read the same per-item entries many times on one worker; this avoids re-reading them.
    Size: STAGES_READ_CACHE_MB (default 1024).
    """

    def __init__(self):
        self.items: "OrderedDict[str, tuple[Any, int]]" = OrderedDict()
        self.bytes = 0
        self.limit = int(os.environ.get("STAGES_READ_CACHE_MB", "1024")) * 2**20

    def get(self, key: str):
        hit = self.items.get(key)
        if hit is None:
            return None
        self.items.move_to_end(key)
        return hit[0]

    def put(self, key: str, value: Any, nbytes: int) -> None:
        if nbytes > self.limit // 4:
            return
        self.items[key] = (value, nbytes)
        self.bytes += nbytes
        while self.bytes > self.limit and self.items:
            _, (_, b) = self.items.popitem(last=False)
            self.bytes -= b

    def drop(self, key: str) -> None:
        hit = self.items.pop(key, None)
        if hit is not None:
            self.bytes -= hit[1]


READ_CACHE = ReadCache()
