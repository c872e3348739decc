"""A sweep's grid: every combination of the values of every --grid axis, in order."""
from __future__ import annotations

import pytest

from stages.errors import PipelineError
from stages.sweep import parse_grid


def test_two_axes_give_their_cartesian_product_in_order():
    assert parse_grid(["mrf.sigma=0.5, 1", "seed=0,1,2"]) == [
        ["mrf.sigma=0.5", "seed=0"], ["mrf.sigma=0.5", "seed=1"], ["mrf.sigma=0.5", "seed=2"],
        ["mrf.sigma=1", "seed=0"], ["mrf.sigma=1", "seed=1"], ["mrf.sigma=1", "seed=2"]]
    assert parse_grid(["k=3"]) == [["k=3"]]


@pytest.mark.parametrize("grid", ["sigma", "=1,2", "sigma=", "sigma=,"])
def test_an_axis_without_a_key_or_values_is_an_error(grid):
    with pytest.raises(PipelineError, match="is not KEY=V1,V2"):
        parse_grid([grid])
