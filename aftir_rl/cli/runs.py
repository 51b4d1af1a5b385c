"""``aftir runs [LOGDIR]``: the run directories under a folder, unfinished ones included.

A run is written under a hidden ``.NAME.partial`` folder and renamed when it finishes
(:func:`aftir_rl.core.files.staged_dir`); a run stopped by Ctrl-C keeps it when it holds a
checkpoint (``--resume`` continues it), and a killed process (``kill -9``, a power cut) leaves
it behind whatever it holds. This command lists the runs and those unfinished folders with their
size and age; ``--remove-unfinished`` deletes the unfinished folders not written to for
``--older-than`` minutes (a live run writes to its folder far more often than that).
"""

from __future__ import annotations

import argparse
import shutil
import stat
import time
from collections.abc import Sequence
from pathlib import Path

from aftir_rl.cli.args import OneLineParser, bounded_float
from aftir_rl.cli.guard import cli
from aftir_rl.core.config import one_line
from aftir_rl.core.errors import ConfigError

__all__ = ["build_parser", "main"]

#: The most entries of a folder looked at (a runs folder holds hundreds, not millions).
MAX_ENTRIES = 100_000


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir runs``."""
    parser = OneLineParser(
        prog="aftir runs",
        description="List the run directories under LOGDIR and the unfinished runs a stopped or "
        "killed process left (hidden .NAME.partial folders); optionally remove old ones.",
    )
    parser.add_argument("logdir", nargs="?", default="runs", help="the runs folder (runs)")
    parser.add_argument(
        "--remove-unfinished",
        action="store_true",
        help="delete the unfinished folders not written to for --older-than minutes",
    )
    parser.add_argument(
        "--older-than",
        type=bounded_float(1.0, 1e6),
        default=60.0,
        metavar="MIN",
        help="how long an unfinished folder must have been untouched to be removed (60)",
    )
    return parser


def _size_and_newest(folder: Path) -> tuple[int, float]:
    """Bytes of the files in ``folder`` and the latest modification time in it, in one walk."""
    size, newest = 0, folder.stat().st_mtime
    for count, path in enumerate(folder.rglob("*")):
        if count >= MAX_ENTRIES:
            break
        try:
            info = path.lstat()
        except OSError:
            continue
        newest = max(newest, info.st_mtime)
        size += info.st_size if stat.S_ISREG(info.st_mode) else 0
    return size, newest


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir runs``."""
    args = build_parser().parse_args(argv)
    root = Path(args.logdir)
    if not root.is_dir():
        raise ConfigError(f"{root}: not a folder")
    entries = sorted(p for _, p in zip(range(MAX_ENTRIES), root.iterdir()))
    folders = [p for p in entries if p.is_dir() and not p.is_symlink()]
    unfinished = [p for p in folders if p.name.startswith(".") and p.name.endswith(".partial")]
    finished = [p for p in folders if not p.name.startswith(".")]
    now = time.time()
    for run in finished:
        print(one_line(run.name))
    removed = 0
    for folder in unfinished:
        size, newest = _size_and_newest(folder)
        age = (now - newest) / 60.0
        facts = f"{size / 1e6:.1f} MB, last written {age:.0f} min ago"
        if args.remove_unfinished and age >= args.older_than:
            shutil.rmtree(folder)
            removed += 1
            print(f"removed unfinished {one_line(folder.name)} ({facts})")
        else:
            print(f"unfinished {one_line(folder.name)} ({facts}; --resume continues it if it "
                  "holds a checkpoint)")  # fmt: skip
    print(
        f"{len(finished)} runs, {len(unfinished) - removed} unfinished in {root}"
        + (f"; {removed} removed" if removed else "")
    )
    return 0
