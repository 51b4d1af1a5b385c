from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.robot import Posture, tip_position
from aftir_rl.core.tank import load_tank
from aftir_rl.experiments.bench import Outcome, Row, format_table, run_benchmark, target_sets
from aftir_rl.planning.posture import Planner


def test_summary_counts_only_what_ran():
    row = Row(
        "s",
        "m",
        [
            Outcome(True, 0.1, 2.0, 100.0, 1.0),
            Outcome(True, 0.3, 1.0, 300.0, 3.0),
            Outcome(False, seconds=5.0, note="no posture"),
            Outcome(False, ran=False, note="not run"),
        ],
    )
    s = row.summary()
    assert s["targets"] == 3 and s["not_run"] == 1
    assert s["success_rate"] == pytest.approx(2 / 3)
    assert s["tip_error_cm"] == pytest.approx(0.2) and s["path_cm"] == pytest.approx(200.0)
    assert s["min_clearance_cm"] == 1.0 and s["seconds"] == 3.0
    assert s["notes"] in ("no posture; ...", "not run; ...")
    table = format_table([row])
    assert table.splitlines()[2].startswith(
        "| s | m | 3 (+1 not run) | 67% | 0.2 | 1.00 | – | 200 |"
    )


def test_target_sets_are_fixed_and_free():
    a, b = target_sets(3, seed=7), target_sets(3, seed=7)
    assert a.keys() == {"jace", "icra2014", "st2014", "filomat2018", "bay1", "bay2"}
    for name in a:
        assert all(
            ta == tb and np.array_equal(xa, xb) for (ta, xa), (tb, xb) in zip(a[name], b[name])
        )
    planner = Planner("b737_center")
    assert all(not planner.beyond_baffle(t) for _, t in a["bay1"])
    assert all(planner.beyond_baffle(t) for _, t in a["bay2"])
    assert len(a["st2014"]) == 12 and len(a["icra2014"]) == 4


@pytest.mark.slow
def test_benchmark_outcomes_check_out(tank):
    sets = {"bay1": [("b737_center", np.array([20.0, 10.0, 60.0]))]}
    methods = {"bay1": ("tga", "rrt_connect", "q_table+postures")}
    rows = run_benchmark(sets, methods, rrt_seconds=20)
    by_method = {r.method: r for r in rows}
    target = sets["bay1"][0][1]
    tga = by_method["tga"].outcomes[0]
    assert tga.success and tga.tip_error_cm < 0.01 and math.isnan(tga.path_cm)
    rrt = by_method["rrt_connect"].outcomes[0]
    assert rrt.success, rrt.note
    # The RRT path goes at least as far as the straight line from the start point to the target.
    assert rrt.path_cm >= np.linalg.norm(target - np.array(tank.start_point)) - 1e-6
    q = by_method["q_table+postures"].outcomes[0]
    # A complete trajectory here (its first move bridged), its tip on the target, its motion
    # clear of the tank and at least as long as the straight line from the start point.
    assert q.success and q.note == "", q.note
    assert q.tip_error_cm < 0.01 and q.clearance_cm >= 0.0
    assert q.path_cm >= np.linalg.norm(target - np.array(tank.start_point)) - 1e-6


@pytest.mark.slow
def test_bench_cli(tmp_path):
    out = tmp_path / "bench.json"
    run = subprocess.run(
        [sys.executable, "-m", "aftir_rl.bench", "--sets", "jace", "--quiet", "--json", str(out)]
        + ["--quick", "--rrt-seconds", "2"],
        capture_output=True,
        text=True,
        check=True,
    )
    # --quick takes its values for the options left at default, and the header says so.
    assert run.stdout.splitlines()[1] == (
        "quick table (make bench; make bench-full for the full one): the first 2 targets of each "
        "set, 2 random targets per bay "
        "(seed 7); RRT-Connect 2 s per target and 1 s per colliding move"
    )
    lines = [line for line in run.stdout.splitlines() if line.startswith("| jace")]
    assert [line.split("|")[2].strip() for line in lines] == [
        "blind",
        "region_clipping",
        "tga",
        "obstacle_clipping",
    ]
    data = json.loads(out.read_text())
    assert data["machine"]["cores"] >= 1 and data["seconds"] > 0
    assert data["options"]["n_random"] == 2
    tga = next(r for r in data["rows"] if r["method"] == "tga")
    assert tga["success_rate"] == 1.0 and len(tga["outcomes"]) == 2  # --quick: the first 2
    # Every TGA posture of the run is re-checked here, independently of the bench.
    scene = CollisionScene(load_tank("open_space"))
    for t, outcome in zip(((11, 31, 31), (30, 19, 50), (30, 29, 67)), tga["outcomes"]):
        p = Posture(**outcome["posture"])
        assert np.linalg.norm(tip_position(p.dis, p.theta, p.phi, 25) - t) < 0.01
        assert not scene.collides(p)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--model", "nowhere"], "no model.zip"),
        (["--model", "{bad_run}"], "config.json is missing or not a training run's"),
        (["--n-random", "0"], "--n-random must be from 1 to"),
        (["--rrt-seconds", "nan"], "--rrt-seconds must be from 0 to 3600"),
        (["--bridge-seconds", "-1"], "--bridge-seconds must be from 0 to 3600"),
        (["--json", "/nonexistent/dir/out.json"], "cannot write in"),
    ],
)
def test_bench_cli_rejects_bad_input(tmp_path, args, message):
    bad_run = tmp_path / "run"
    bad_run.mkdir()
    (bad_run / "model.zip").write_bytes(b"")
    (bad_run / "config.json").write_text("{}")
    args = [a.replace("{bad_run}", str(bad_run)) for a in args]
    run = subprocess.run(
        [sys.executable, "-m", "aftir_rl.bench", *args], capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 2 and message in run.stderr
    assert "Traceback" not in run.stderr
