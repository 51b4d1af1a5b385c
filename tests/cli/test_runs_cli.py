"""aftir runs: runs and the unfinished folders a killed process leaves, listed and removed."""

from __future__ import annotations

import os
import time

from aftir_rl.cli import runs


def _old(folder, minutes):
    stamp = time.time() - 60 * minutes
    for path in [folder, *folder.rglob("*")]:
        os.utime(path, (stamp, stamp))


def test_unfinished_runs_are_listed_and_only_old_ones_removed(tmp_path, capsys):
    (tmp_path / "ppo__A__1").mkdir()
    stale = tmp_path / ".ppo__A__2.partial"
    live = tmp_path / ".ppo__A__3.partial"
    for folder in (stale, live):
        folder.mkdir()
        (folder / "unfinished.json").write_text("{}")
    _old(stale, 120)
    assert runs.main([str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "ppo__A__1\n" in out and out.count("unfinished .ppo__A__") == 2
    assert "1 runs, 2 unfinished" in out
    assert runs.main([str(tmp_path), "--remove-unfinished"]) == 0
    assert "removed unfinished .ppo__A__2.partial" in capsys.readouterr().out
    assert not stale.exists() and live.exists() and (tmp_path / "ppo__A__1").exists()


def test_a_missing_folder_is_one_line(tmp_path, capsys):
    assert runs.main([str(tmp_path / "nope")]) == 2
    assert capsys.readouterr().err.count("\n") == 1
