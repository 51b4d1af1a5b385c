from __future__ import annotations

import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parent.parent


def test_readme_snippet_runs(capsys):
    text = (ROOT / "README.md").read_text()
    section = text[text.index("### From other RL code") :]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    exec(compile(code, "README.md", "exec"), {})
    assert capsys.readouterr().out.strip() == "True 22 (14, 9, 4)"


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
        assert target.exists(), f"{name}: {link} names no file"
        if anchor:
            body = re.sub(r"```.*?```", "", target.read_text(), flags=re.S)
            slugs = {_slug(h) for h in re.findall(r"^#+ (.+)$", body, re.M)}
            assert anchor in slugs, f"{name}: {link} names no heading of {target.name}"


def test_readme_keeps_the_test_commands():
    """CI runs the README's test commands."""
    text = (ROOT / "README.md").read_text()
    for command in ("make test", "make test-all", "make lint"):
        assert f"`{command}`" in text
