from __future__ import annotations

import argparse
import html
import importlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

import aftir_rl
from aftir_rl.cli.main import SUBCOMMANDS

ROOT = Path(__file__).resolve().parent.parent


def test_readme_grid_world_example_runs(capsys):
    """The README's first Python example, in this process: it prints what the README says."""
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## The environments") :]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    exec(compile(code, "README.md", "exec"), {})
    assert capsys.readouterr().out.splitlines()[0] == "True 22"


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(p.name for p in (ROOT / "notebooks").glob("*.ipynb")))
def test_notebook_executes(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # anything the notebook writes goes to tmp_path
    nb = nbformat.read(ROOT / "notebooks" / name, as_version=4)
    NotebookClient(
        nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    ).execute()
    errors = [
        o
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.get("outputs", [])
        if o.output_type == "error"
    ]
    assert not errors


def _slug(heading: str) -> str:
    """GitHub's anchor of a markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


#: Pages the docs build writes (docs/_ext/aftir_docs.py), absent from a fresh clone.
GENERATED = {"docs/cli.md", "docs/pretrained.md"}

DOCS = ["README.md", *sorted(f"docs/{p.name}" for p in (ROOT / "docs").glob("*.md"))]


@pytest.mark.parametrize("name", DOCS)
def test_doc_links_resolve(name):
    """Every relative link of the README and docs/ names a file, and an anchor a heading there."""
    path = ROOT / name
    text = path.read_text()
    links = re.findall(r"\]\(([^)\s]+)\)", text)
    assert name != "README.md" or any(link.startswith("docs/") for link in links)
    for link in links:
        if re.match(r"[a-z]+:", link):
            continue
        file, _, anchor = link.partition("#")
        target = (path.parent / file).resolve() if file else path
        if target.relative_to(ROOT).as_posix() in GENERATED and not target.exists():
            continue  # written by the docs build; test_site_builds... follows these links
        assert target.exists(), f"{name}: {link} names no file"
        if anchor:
            body = re.sub(r"```.*?```", "", target.read_text(), flags=re.S)
            slugs = {_slug(h) for h in re.findall(r"^#+ (.+)$", body, re.M)}
            assert anchor in slugs, f"{name}: {link} names no heading of {target.name}"


def test_readme_keeps_the_test_commands():
    """CI runs the README's test commands."""
    text = (ROOT / "README.md").read_text()
    for command in ("make test", "make test-all", "make fuzz", "make lint", "make docs"):
        assert re.search(rf"^{command}( |$)", text, re.M), command


# --- The documentation site -------------------------------------------------------------------


def _options(parser: argparse.ArgumentParser) -> set[str]:
    """Every option string of a parser and of its subcommands' parsers."""
    found = set()
    for action in parser._actions:
        found.update(action.option_strings)
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                found |= _options(sub)
    return found


@pytest.mark.slow
def test_site_builds_offline_without_warnings_and_its_links_resolve():
    """``make docs``'s build: zero warnings (a missing heading anchor is one), a page per env id,
    every subcommand's options on the CLI page, and no internal link LinkChecker cannot follow."""
    # LinkChecker run as root reads as the user nobody: the site goes where nobody can read it.
    site = Path(tempfile.mkdtemp(prefix="aftir-site-"))
    site.chmod(0o755)
    try:
        _check_site(site / "html")
    finally:
        shutil.rmtree(site)


def _check_site(out: Path) -> None:
    build = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html"]
        + [str(ROOT / "docs"), str(out)],
        capture_output=True,
        text=True,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
        timeout=600,
    )
    assert build.returncode == 0, build.stderr[-5000:]
    for env_id in aftir_rl.ENV_IDS:
        page = (out / "envs" / f"{env_id}.html").read_text()
        assert "Observation space" in page and f"{env_id}.png" in page
    cli = html.unescape(re.sub(r"<[^>]+>", "", (out / "cli.html").read_text()))
    for name, (module, _) in SUBCOMMANDS.items():
        assert f"aftir {name}" in cli
        for option in _options(importlib.import_module(module).build_parser()) - {"-h", "--help"}:
            assert option in cli, f"aftir {name} {option}"
    checker = Path(sys.executable).with_name("linkchecker")
    links = subprocess.run(
        [str(checker), "--no-status", "--no-warnings", (out / "index.html").as_uri()],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert links.returncode == 0, links.stdout[-5000:]
    assert "0 errors found" in links.stdout


def test_results_page_is_what_the_benchmark_json_gives():
    """docs/results.md and the README's results table are rendered from benchmarks/results/."""
    run = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "results_page.py"), "--check"],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr


# --- docs/design.md against the package -------------------------------------------------------


def _layer_table() -> dict[str, list[str]]:
    """docs/design.md §1's layer table: ``"N name"`` -> its modules cell, row by row."""
    text = (ROOT / "docs" / "design.md").read_text()
    section = text[text.index("## 1. Layers") : text.index("## 2.")]
    rows = [line.split("|")[1:-1] for line in section.splitlines() if line.startswith("| ")]
    return {cells[0].strip(): cells[1] for cells in rows[1:]}


def _listed_modules(cell: str) -> tuple[list[str], list[str]]:
    """The dotted modules one row names, and the sub-packages it refers to another section for.

    The cell opens with its layer's package (```aftir_rl.core```); then a name is a module of
    the package opened last, ```name/``` a sub-package, followed by its modules in parentheses
    or by ``(§N)``, the section that lists them; a dotted ```aftir_rl...``` name stands alone.
    """
    tokens = re.findall(r"`([^`]+)`|(\(§\d+\))|([()])", cell)
    prefix = [tokens[0][0]]
    listed, elsewhere, last = [tokens[0][0]], [], ""
    for name, section, paren in tokens[1:]:
        if section:
            elsewhere.append(last)
        elif paren == "(":
            prefix.append(last)
        elif paren == ")":
            prefix.pop()
        elif name.startswith("aftir_rl"):
            listed.append(name)
        else:
            last = f"{prefix[-1]}.{name.rstrip('/')}"
            listed.append(last)
    return listed, elsewhere


def test_design_layer_table_lists_every_module_of_the_package():
    """§1's table names each module once, nothing that does not exist, in the layers
    tests/test_layers.py checks the imports against."""
    from tests.test_layers import LAYERS, _layer

    package = ROOT / "aftir_rl"
    modules = {
        ".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        for p in package.rglob("*.py")
        if p.name != "__main__.py"
    }
    table = _layer_table()
    assert list(table) == [f"{n} {name}" for name, n in sorted(LAYERS.items(), key=lambda x: x[1])]
    listed: list[str] = []
    for row, cell in table.items():
        names, elsewhere = _listed_modules(cell)
        layer = int(row.split()[0])
        assert all(_layer(m) == layer for m in names), row
        listed += names
        modules -= {m for m in modules for p in elsewhere if m.startswith(f"{p}.")}
    assert len(listed) == len(set(listed)), "a module listed twice"
    assert sorted(set(listed) - modules) == [], "listed, but no module of the package"
    assert sorted(modules - set(listed)) == [], "modules the table leaves out"
