"""The package's house, read from the source (AST): layers, cycles, private names, a light import.

Layers, lowest first (docs/design.md §1): a module may import from its own layer or a lower
one, never from a higher one. Imports inside functions and under ``TYPE_CHECKING`` count too.
Sizes are a review aid, not a test: ``make house`` (scripts/house_report.py).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")  # Python 3.11+

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "aftir_rl"

#: Sub-package -> layer (lowest first). The top-level ``python -m`` shims are command lines.
LAYERS = {"core": 0, "viz": 1, "planning": 2, "envs": 3, "rl": 4, "experiments": 5, "cli": 6}
SHIMS = {"train", "plan", "evaluate", "bench", "tune", "tank", "view"}
#: The root package registers the envs: it sits with them.
ROOT_LAYER = LAYERS["envs"]


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in PACKAGE.rglob("*.py")}


def _layer(module: str) -> int:
    parts = module.split(".")
    if len(parts) == 1:
        return ROOT_LAYER
    if parts[1] in SHIMS:
        return LAYERS["cli"]
    return LAYERS[parts[1]]


def _is_package(module: str) -> bool:
    return MODULES[module].name == "__init__.py"


def _imports(module: str) -> list[tuple[str, str]]:
    """(imported module of this package, imported name or "") for every import of ``module``."""
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")[
                    : len(module.split(".")) - node.level + _is_package(module)
                ]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for alias in node.names:
                full = f"{target}.{alias.name}"
                out.append((full if full in MODULES else target, alias.name))
        elif isinstance(node, ast.Import):
            out += [(alias.name, "") for alias in node.names]
    return [(m, name) for m, name in out if m in MODULES]


GRAPH = {m: {t for t, _ in _imports(m) if t != m} for m in MODULES}


def test_every_module_has_a_layer():
    assert {_layer(m) for m in MODULES} <= set(LAYERS.values())


def test_imports_point_down_the_layers():
    upward = [
        f"{m} (layer {_layer(m)}) imports {t} (layer {_layer(t)})"
        for m, targets in GRAPH.items()
        for t in targets
        if _layer(t) > _layer(m)
    ]
    assert upward == []


def test_no_import_cycles():
    # a package's __init__ re-exporting its modules is not a cycle (as house_check counts)
    graph = {m: {t for t in ts if not _is_package(t)} for m, ts in GRAPH.items()}
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(u: str, stack: list[str]) -> None:
        state[u] = 1
        stack.append(u)
        for v in sorted(graph[u]):
            if state.get(v) == 1:
                cycles.append(stack[stack.index(v) :] + [v])
            elif not state.get(v):
                visit(v, stack)
        stack.pop()
        state[u] = 2

    for m in sorted(graph):
        if not state.get(m):
            visit(m, [])
    assert cycles == []


def test_no_private_name_imported_from_another_module():
    private = [
        f"{m} imports {name} from {t}"
        for m in MODULES
        for t, name in _imports(m)
        if name.startswith("_") and not name.startswith("__") and t != m
    ]
    assert private == []


def test_pyproject_lists_every_package():
    with open(ROOT / "pyproject.toml", "rb") as fh:
        listed = set(tomllib.load(fh)["tool"]["setuptools"]["packages"])
    folders = {m for m in MODULES if _is_package(m)}
    data = ("aftir_rl.configs", "aftir_rl.rl.policies")  # folders of data, shipped as packages
    assert {p for p in listed if not p.startswith(data)} == folders


def test_import_aftir_rl_is_light():
    heavy = ("numba", "fcl", "torch", "plotly", "stable_baselines3")
    code = (
        "import sys, aftir_rl, gymnasium as gym; gym.spec('AFTIR-ArmFTL-v0'); "
        f"print([m for m in {heavy!r} if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
