"""Every tuning number in ``corr_core`` is a keyword-only argument: a call reads
``refine_extrinsic(S, T, p2p, n_patches=150)``, never ``refine_extrinsic(S, T, p2p, 150)``."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

CORR_CORE = Path(__file__).resolve().parents[2] / "corr_core"


def _is_number(node: ast.AST, constants: set[str]) -> bool:
    """A number literal (bools are flags), arithmetic on them (``2 / 3``), or a module constant holding one."""
    if isinstance(node, ast.Constant):
        return type(node.value) in (int, float)
    if isinstance(node, ast.BinOp):
        return _is_number(node.left, constants) and _is_number(node.right, constants)
    if isinstance(node, ast.UnaryOp):
        return _is_number(node.operand, constants)
    return isinstance(node, ast.Name) and node.id in constants


def positional_numbers(source: str) -> list[str]:
    """"function(parameter)" of each positional parameter whose default is a number or a module-level constant
    holding one (``keep_fraction=CHIRALITY_POOL``)."""
    tree = ast.parse(source)
    constants: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.Assign) and _is_number(node.value, constants):
            constants |= {t.id for t in node.targets if isinstance(t, ast.Name)}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            with_default = a.args[len(a.args) - len(a.defaults):]
            found += [f"{node.name}({p.arg})" for p, d in zip(with_default, a.defaults) if _is_number(d, constants)]
    return found


@pytest.mark.parametrize("module", sorted(str(p.relative_to(CORR_CORE)) for p in CORR_CORE.rglob("*.py")))
def test_tuning_numbers_are_keyword_only(module):
    assert positional_numbers((CORR_CORE / module).read_text()) == []


def test_the_check_sees_a_positional_number_and_not_a_keyword_only_one():
    assert positional_numbers("def f(a, b=2, *, c=0.5, flag=True): pass\ndef g(x, y=True): pass") == ["f(b)"]
    source = "POOL = 2 / 3\nPLAN = 'a+b'\ndef f(a, keep=POOL, plan=PLAN, *, other=POOL): pass"
    assert positional_numbers(source) == ["f(keep)"]
