"""The package's largest modules, functions and module docstrings, as a review aid.

    python scripts/house_report.py [--top N]

Run by ``make house``. Prints three lists, longest first, with the sizes the package was written
to (modules 450 lines, functions 60 outside compiled kernels, module docstrings 15) and which
entries pass them: a reviewer's pointer to what may read better split, not a test. It never
fails on a size; code is as long as it reads best. Imports, cycles and private names are tested
(``tests/test_layers.py``).
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "aftir_rl"
#: The sizes the package was written to (lines): above them is worth a second look.
GUIDES = {"module": 450, "function": 60, "docstring": 15}


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def measure(package: Path = PACKAGE) -> dict[str, list[tuple[str, int]]]:
    """Lines per module, per function (compiled kernels left out) and per module docstring."""
    sizes: dict[str, list[tuple[str, int]]] = {kind: [] for kind in GUIDES}
    for path in sorted(package.rglob("*.py")):
        name, text = _module_name(path), path.read_text(encoding="utf-8")
        tree = ast.parse(text)
        sizes["module"].append((name, len(text.splitlines())))
        doc = ast.get_docstring(tree)
        if doc:
            sizes["docstring"].append((name, len(doc.splitlines())))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                if any("njit" in ast.unparse(d) for d in node.decorator_list):
                    continue
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                sizes["function"].append((f"{name}.{node.name}", lines))
    return {kind: sorted(rows, key=lambda r: (-r[1], r[0])) for kind, rows in sizes.items()}


def main() -> None:
    """Print the ``--top`` largest of each kind and how many pass the guide."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--top", type=int, default=10, help="entries per list (default 10)")
    args = parser.parse_args()
    titles = {"module": "Modules", "function": "Functions", "docstring": "Module docstrings"}
    for kind, rows in measure().items():
        guide = GUIDES[kind]
        over = sum(n > guide for _, n in rows)
        print(f"{titles[kind]}: {len(rows)}, {over} over {guide} lines")
        for name, n in rows[: args.top]:
            print(f"  {n:5d}  {name}" + ("  (over)" if n > guide else ""))
        print()


if __name__ == "__main__":
    main()
