"""experiments/route_dagger.py runs end to end: clone, one DAgger round, evaluations, JSON."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).parents[2]


def test_route_dagger_runs_and_writes_its_rounds(tmp_path):
    out = tmp_path / "rounds.json"
    args = ["--routes", "4", "--rounds", "1", "--eval", "4", "--updates", "20", "--json", str(out)]
    script = ROOT / "experiments" / "route_dagger.py"
    done = subprocess.run(
        [sys.executable, str(script), *args], capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    rounds = json.loads(out.read_text())["rounds"]
    assert [r["round"] for r in rounds] == [0, 1]
    assert rounds[1]["states"] > rounds[0]["states"] > 0
    assert rounds[1]["teacher"]["answered"] >= rounds[0]["states"]
    last = rounds[1]["backtrack"]
    assert 0.0 <= last["motions_keeping_1cm"] <= last["success"] <= 1.0
