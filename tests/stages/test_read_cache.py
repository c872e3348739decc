"""The per-process read cache keeps the most recently used entries within its byte budget."""
from __future__ import annotations

from stages.read_cache import ReadCache

KB = 2**10


def test_the_least_recently_used_entry_goes_first(monkeypatch):
    monkeypatch.setenv("STAGES_READ_CACHE_MB", "1")                  # 1024 KiB; an entry may take 256 KiB
    cache = ReadCache()
    for name in "abcde":
        cache.put(name, name.upper(), 200 * KB)                       # 1000 KiB: all kept
    assert [cache.get(name) for name in "abcde"] == list("ABCDE") and cache.bytes == 1000 * KB
    assert cache.get("a") == "A"                                      # used again: now the most recent
    cache.put("f", "F", 200 * KB)                                     # over budget: 'b' (least recent) goes
    assert cache.get("b") is None
    assert [cache.get(name) for name in "acdef"] == list("ACDEF") and cache.bytes == 1000 * KB


def test_a_big_entry_is_not_kept_and_drop_forgets(monkeypatch):
    monkeypatch.setenv("STAGES_READ_CACHE_MB", "1")
    cache = ReadCache()
    cache.put("big", "B", 300 * KB)                                   # more than a quarter of the budget
    assert cache.get("big") is None and cache.bytes == 0
    cache.put("x", "X", 10 * KB)
    cache.drop("x")
    cache.drop("never stored")
    assert cache.get("x") is None and cache.bytes == 0
