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
