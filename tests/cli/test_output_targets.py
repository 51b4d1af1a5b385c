"""Every writing command against hostile output targets: nothing but the named output changes.

Each command that takes ``-o`` (and ``tank export``'s ``--walls``/``--yaml``) is pointed at a
FIFO, a character device (``/dev/full``'s numbers, made in the test folder), a symbolic link to
a file outside, a dangling link, a folder, one of its own inputs, a private regular file and a
path under a regular file. Whatever the command answers (exit 0 or 2, one line on stderr for 2,
no traceback), every file of the test folder but the named output must be as it was: no device,
FIFO or link replaced, no file behind a link written, no input changed, nothing created
elsewhere; a regular file that is replaced keeps its mode.
"""

from __future__ import annotations

import hashlib
import os
import stat
from collections.abc import Callable
from pathlib import Path

import pytest

from aftir_rl.cli import export, tank, view
from aftir_rl.rl.tabular import QLearningConfig
from aftir_rl.rl.tabular.train import train_q_table

TARGETS = ["fifo", "device", "link_out", "dangling", "folder", "input", "private", "under_file"]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """A Q-table run with its timed motion, and a generated tank YAML."""
    top = tmp_path_factory.mktemp("inputs")
    (summary,) = train_q_table(
        QLearningConfig(episodes=300), [(230, 140, 90)], logdir=top, progress_bar=False
    )
    yaml = top / "wing.yaml"
    assert tank.main(["generate", "--bays", "2", "--seed", "3", "-o", str(yaml)]) == 0
    return {"run": Path(summary["run_dir"]), "yaml": yaml}


def _commands(inputs: dict[str, Path]) -> dict[str, tuple[Callable[[list[str]], int], list[str]]]:
    """Each writing command: its main, its arguments before the output, and its input file."""
    run, yaml = str(inputs["run"]), str(inputs["yaml"])
    return {
        "export": (export.main, [run, "-o"]),
        "view": (view.main, [run, "-o"]),
        "tank generate": (tank.main, ["generate", "--bays", "2", "--seed", "1", "-o"]),
        "tank export": (tank.main, ["export", "--tank", yaml, "-o"]),
        "tank export --walls": (
            tank.main,
            ["export", "--tank", yaml, "-o", "{tmp}/solids.stl", "--walls"],
        ),
        "tank export --yaml": (
            tank.main,
            ["export", "--tank", yaml, "-o", "{tmp}/solids.stl", "--yaml"],
        ),
    }


def _make_target(kind: str, where: Path, an_input: Path, suffix: str) -> Path:
    """The hostile output path of ``kind`` in ``where``, named ``out<suffix>``."""
    outside = where / "outside.txt"
    outside.write_text("not yours\n")
    path = where / f"out{suffix}"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "device":
        if os.geteuid() != 0:
            pytest.skip("making a device node needs root")
        os.mknod(path, stat.S_IFCHR | 0o666, os.makedev(1, 7))  # /dev/full's numbers
    elif kind == "link_out":
        path.symlink_to(outside)
    elif kind == "dangling":
        path.symlink_to(where / "nowhere" / "file")
    elif kind == "folder":
        path.mkdir()
        (path / "keep.txt").write_text("kept\n")
    elif kind == "input":
        path = an_input
    elif kind == "private":
        path.write_text("secret\n")
        path.chmod(0o600)
    elif kind == "under_file":
        path = outside / f"out{suffix}"
    return path


def _snapshot(*roots: Path) -> dict[str, tuple]:
    """Every entry under ``roots``: its type, mode, link text or content hash."""
    found: dict[str, tuple] = {}
    for root in roots:
        for p in [root, *root.rglob("*")]:
            info = os.lstat(p)
            if stat.S_ISLNK(info.st_mode):
                found[str(p)] = ("link", os.readlink(p))
            elif stat.S_ISREG(info.st_mode):
                digest = hashlib.sha256(p.read_bytes()).hexdigest()
                found[str(p)] = ("file", stat.S_IMODE(info.st_mode), digest)
            elif stat.S_ISDIR(info.st_mode):
                found[str(p)] = ("dir",)
            else:
                found[str(p)] = ("special", stat.S_IFMT(info.st_mode), info.st_rdev)
    return found


@pytest.mark.parametrize("kind", TARGETS)
@pytest.mark.parametrize(
    "command",
    ["export", "view", "tank generate", "tank export", "tank export --walls", "tank export --yaml"],
)
def test_a_hostile_output_changes_nothing_but_itself(inputs, tmp_path, capsys, command, kind):
    main, args = _commands(inputs)[command]
    an_input = inputs["yaml"] if command.startswith("tank") else inputs["run"] / "trajectory.json"
    if command == "tank generate" and kind == "input":
        pytest.skip("tank generate reads no file")
    suffix = {"export": ".json", "view": ".html", "tank generate": ".yaml"}.get(command, ".stl")
    out = _make_target(kind, tmp_path, an_input, ".yaml" if "--yaml" in command else suffix)
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    before = _snapshot(tmp_path, inputs["run"], inputs["yaml"])
    capsys.readouterr()
    code = main([*args, str(out)])
    stdout, stderr = capsys.readouterr()
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert code in (0, 2) and "Traceback" not in stderr, stderr
    assert code == 0 or len(lines) == 1, stderr
    after = _snapshot(tmp_path, inputs["run"], inputs["yaml"])
    written = {str(out), str(tmp_path / "solids.stl")} if code == 0 else set()
    changed = {p for p in before.keys() | after.keys() if before.get(p) != after.get(p)}
    assert changed <= written, (code, stderr, sorted(changed - written))
    if kind in ("fifo", "device", "link_out", "dangling", "folder", "input", "under_file"):
        assert code == 2, f"{command} wrote to {kind}: {stdout}"
    if kind == "private":
        assert code == 0 and stat.S_IMODE(os.lstat(out).st_mode) == 0o600
