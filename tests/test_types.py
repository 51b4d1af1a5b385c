"""The package's glue is typed: parameters and fields that name a domain object are not ``Any``.

A parameter or dataclass field called ``config``, ``env``, ``model``, ``tank``, ``agent``,
``spec`` or ``venv`` says what it holds with its type (a ``TYPE_CHECKING`` import where the
class lives in a higher layer), so strict mypy checks what flows through it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import aftir_rl

PACKAGE = Path(aftir_rl.__file__).parent
NAMES = {"config", "env", "model", "tank", "agent", "spec", "venv"}


def _is_any(annotation: ast.expr | None) -> bool:
    if isinstance(annotation, ast.Name):
        return annotation.id == "Any"
    if isinstance(annotation, ast.Attribute):
        return annotation.attr == "Any"
    return isinstance(annotation, ast.Constant) and annotation.value == "Any"


def _any_typed(tree: ast.AST) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            a = node.args
            for arg in [*a.posonlyargs, *a.args, *a.kwonlyargs, a.vararg, a.kwarg]:
                if arg is not None and arg.arg in NAMES and _is_any(arg.annotation):
                    found.append((arg.lineno, f"{node.name}({arg.arg})"))
        if isinstance(node, ast.ClassDef):
            for item in node.body:
                if (
                    isinstance(item, ast.AnnAssign)
                    and isinstance(item.target, ast.Name)
                    and item.target.id in NAMES
                    and _is_any(item.annotation)
                ):
                    found.append((item.lineno, f"{node.name}.{item.target.id}"))
    return found


def test_the_scan_finds_what_it_looks_for():
    code = "class C:\n    env: Any\n\ndef f(tank: typing.Any, model: 'Any', seed: Any): ...\n"
    assert [what for _, what in _any_typed(ast.parse(code))] == ["C.env", "f(tank)", "f(model)"]


def test_no_domain_parameter_is_typed_any():
    found = [
        f"{path.relative_to(PACKAGE.parent)}:{line}: {what}"
        for path in sorted(PACKAGE.rglob("*.py"))
        for line, what in _any_typed(ast.parse(path.read_text(encoding="utf-8")))
    ]
    assert found == []
