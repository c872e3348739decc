"""A parsed manifest is trusted only when it is complete, of this format, of this key and matches its checksum."""
from __future__ import annotations

from stages.manifest import FORMAT_VERSION, manifest_checksum, manifest_problem, same_content


def _manifest(key: str, **changes) -> dict:
    doc = {"format": FORMAT_VERSION, "key": key, "created": 1.0, "tree": {"__array__": "a0"},
           "arrays": {"a0": {"sha": "00", "shape": [3], "dtype": "float64"}}, "files": {}, "info": {"stage": "s"}}
    doc.update(changes)
    return {**doc, "checksum": manifest_checksum(doc)}


def test_a_sound_manifest_is_trusted_and_each_defect_is_named():
    key = "ab" * 16
    assert manifest_problem(_manifest(key), key) is None
    assert manifest_problem(_manifest(key), "cd" * 16) == "belongs to another entry"   # copied under another key
    assert manifest_problem(_manifest(key, format=1), key).startswith("has format 1")
    edited = {**_manifest(key), "tree": 5}
    assert manifest_problem(edited, key) == "does not match its checksum (edited or damaged)"
    assert manifest_problem({k: v for k, v in _manifest(key).items() if k != "info"}, key) == "is incomplete"
    assert manifest_problem(_manifest(key, files={"a.txt": {"sha": "1"}}), key) == "is malformed"
    assert manifest_problem([1, 2], key) == "is incomplete"


def test_same_content_compares_the_value_not_the_time():
    key = "ab" * 16
    assert same_content(_manifest(key), _manifest(key, created=2.0))
    assert not same_content(_manifest(key), _manifest(key, tree=3))
    assert not same_content(_manifest(key), _manifest(key, info={"left_out": [["k", "t", "i", "why"]]}))
