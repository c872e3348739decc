"""The marker of a skipped per-mesh result (shapecorr/skips.py): stored by the engine's codec like any result, and
read back as skipped, with its reason."""
from __future__ import annotations

import numpy as np

from shapecorr.skips import is_skipped, skip_reason, skip_reasons, skipped
from stages.codec import decode, encode


def test_a_skipped_result_is_stored_and_read_back_as_skipped():
    arrays: dict = {}
    back = decode(encode(skipped("mesh002: no landmarks"), arrays), arrays)
    assert arrays == {} and is_skipped(back) and skip_reason(back) == "mesh002: no landmarks"


def test_results_with_a_map_are_not_skipped():
    result = {"vertex_map": np.arange(3), "hypothesis": 0}
    assert not is_skipped(result) and skip_reason(result) is None and not is_skipped(None)
    assert skip_reasons({"b": skipped("why b"), "a": result, "c": skipped("why c")}) == {"b": "why b",
                                                                                         "c": "why c"}
    assert skip_reasons(None) == {}


def test_only_the_engines_skipped_value_is_skipped():
    from shapecorr.skips import without_skipped

    assert not is_skipped({"skipped": "a result that happens to have this key"})
    assert without_skipped({"a": skipped("why"), "b": {"all": 1}}) == {"b": {"all": 1}}
    assert without_skipped(None) == {}


def test_holds_is_true_only_for_a_computed_result_with_the_key():
    from shapecorr.skips import holds

    assert holds({"vertex_map": np.arange(3)}, "vertex_map")
    assert not holds({"no_truth": "why"}, "vertex_map") and not holds(None, "vertex_map")
    assert not holds(skipped("mesh002: no landmarks"), "vertex_map")
