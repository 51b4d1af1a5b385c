from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from aftir_rl.core.robot import tip_position


def _run(*args):
    return subprocess.run(
        [sys.executable, "-m", "aftir_rl.plan", *args], capture_output=True, text=True
    )


def test_json_schema_and_fk():
    proc = _run("--target", "230", "140", "90", "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert set(out) == {
        "dis",
        "theta",
        "phi",
        "section_length",
        "tip",
        "target",
        "error_cm",
        "clearance_cm",
        "method",
        "seconds",
    }
    assert out["method"] == "tsm" and out["section_length"] == 50
    tip = tip_position(out["dis"], out["theta"], out["phi"], out["section_length"])
    assert np.linalg.norm(tip - [230, 140, 90]) < 0.01 and out["error_cm"] < 0.01


def test_table_and_open_space():
    proc = _run("--target", "30", "18", "51", "--tank", "open_space", "--method", "tga")
    assert proc.returncode == 0 and "theta [deg]" in proc.stdout and "method tga" in proc.stdout
    out = json.loads(_run("--target", "30", "18", "51", "--tank", "open_space", "--json").stdout)
    assert out["clearance_cm"] is None  # nothing to measure against in open space


def test_unreachable_exits_2_without_traceback():
    proc = _run("--target", "0", "20", "85")
    assert proc.returncode == 2
    assert (
        proc.stderr.startswith("error: Cannot reach the target:") and "Traceback" not in proc.stderr
    )


def test_does_not_import_torch():
    code = (
        "import sys, aftir_rl.cli.plan; "
        "print('torch' in sys.modules, 'stable_baselines3' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
