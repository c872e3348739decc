"""Every tuning number of the dense-map modules is a keyword-only argument: a call reads
``refine_extrinsic(S, T, p2p, n_patches=150)``, never ``refine_extrinsic(S, T, p2p, 150)``."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

DENSE = Path(__file__).resolve().parents[4] / "corr_core" / "correspondence" / "dense"


def positional_numbers(source: str) -> list[str]:
    """"function(parameter)" of each positional parameter whose default is a number (bools are flags)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            with_default = a.args[len(a.args) - len(a.defaults):]
            found += [f"{node.name}({p.arg})" for p, d in zip(with_default, a.defaults)
                      if isinstance(d, ast.Constant) and type(d.value) in (int, float)]
    return found


@pytest.mark.parametrize("module", sorted(p.name for p in DENSE.glob("*.py")))
def test_tuning_numbers_are_keyword_only(module):
    assert positional_numbers((DENSE / module).read_text()) == []


def test_the_check_sees_a_positional_number_and_not_a_keyword_only_one():
    assert positional_numbers("def f(a, b=2, *, c=0.5, flag=True): pass\ndef g(x, y=True): pass") == ["f(b)"]
