"""The route experiments run end to end: cloning, DAgger, a stream of wings, evaluations, JSON."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).parents[2]


def _run(script: str, args: list[str], out: Path) -> dict:
    """``experiments/SCRIPT ARGS --json OUT`` in a new process; the JSON it wrote."""
    done = subprocess.run(
        [sys.executable, str(ROOT / "experiments" / script), *args, "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(out.read_text())


def test_route_dagger_runs_and_writes_its_rounds(tmp_path):
    args = ["--routes", "3", "--rounds", "1", "--eval", "3", "--updates", "20", "--budget", "10"]
    data = _run("route_dagger.py", args, tmp_path / "runs.json")
    (run,) = data["runs"]
    rounds = run["rounds"]
    assert data["bay"] == 2 and run["seed"] == 0 and data["eval"]["budget"] == 10
    assert [r["round"] for r in rounds] == [0, 1]
    assert rounds[1]["states"] > rounds[0]["states"] > 0
    assert rounds[1]["teacher"]["answered"] >= rounds[0]["states"]
    last = rounds[1]
    assert 0.0 <= last["greedy"]["success"] <= 1.0 and 0.0 <= last["search"]["success"] <= 1.0
    assert sum(last["greedy_failures_go_wrong_at"].values()) == len(last["greedy"]["failed"])
    assert len(last["corners"]) == 4 and data["frozenlake_8x8_steps_per_s"] > 0


def test_route_anytank_trains_on_a_stream_and_evaluates_every_kind_of_tank(tmp_path):
    args = ["--tanks", "2", "--tank-episodes", "2", "--updates", "20", "--wings", "1"]
    args += ["--wing-targets", "2", "--eval", "1", "--suite-targets", "1", "--budgets", "5"]
    (run,) = _run("route_anytank.py", args, tmp_path / "anytank.json")["runs"]
    assert run["stream"] == "wing:3:10000+" and run["wings_met"] == 2 and run["states"] > 0
    rows = run["eval"]
    assert rows["held_out_wings"]["targets"] == 2 and rows["b737_bay2"]["targets"] == 1
    suite = [k for k in rows if k.startswith("suite_")]
    assert len(suite) == 8 and all(rows[k]["targets"] == 1 for k in suite)
    assert all(0.0 <= rows[k]["search_5"] <= 1.0 for k in suite)
