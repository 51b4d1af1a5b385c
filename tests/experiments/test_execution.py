"""aftir check and aftir export: a planned motion passes, a broken one fails, files round-trip."""

from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from aftir_rl.cli import check as check_cli
from aftir_rl.cli import export as export_cli
from aftir_rl.core.cables import cable_lengths
from aftir_rl.core.errors import CheckpointError
from aftir_rl.experiments.execution import check_motion, export_motion, read_timed
from aftir_rl.planning.ftl.plan import plan_motion
from aftir_rl.planning.timing import joint_positions

pytest.importorskip("toppra")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, tank):
    """A run directory with a planned, timed follow-the-leader motion to a bay-2 target."""
    plan = plan_motion(tank, (181.5, 111.6, 51.5))
    assert plan.complete and plan.timing is not None
    folder = tmp_path_factory.mktemp("runs") / "motion"
    folder.mkdir()
    (folder / "trajectory.json").write_text(json.dumps(plan.to_json()))
    (folder / "path.json").write_text(json.dumps({"tank": "b737_center"}))
    return folder


def _edited(run_dir, tmp_path, edit):
    """A copy of the run with its trajectory.json changed by ``edit(data)``."""
    copy = tmp_path / "edited"
    shutil.copytree(run_dir, copy)
    data = json.loads((copy / "trajectory.json").read_text())
    edit(data)
    (copy / "trajectory.json").write_text(json.dumps(data))
    return copy


def test_a_planned_motion_passes(run_dir, capsys):
    assert check_cli.main([str(run_dir)]) == 0
    assert ": ok (" in capsys.readouterr().out


def _faster(data):
    data["timing"]["t"] = [t / 2 for t in data["timing"]["t"]]


def _back_in_time(data):
    data["timing"]["t"][5] = data["timing"]["t"][3]


def _into_the_wall(data):
    entry = data["motion"][-1]
    entry["dis"] += 100.0  # pushed 1 m further: through the far wall or the ceiling


def _stored_speed(data):
    data["timing"]["velocities"][10][0] = 6.0  # the module's limit is 5 cm/s


@pytest.mark.parametrize(
    "edit, problem",
    [
        (_faster, "times its speed limit"),
        (_back_in_time, "time goes back"),
        (_stored_speed, "dis's speed at entry 10"),
    ],
)
def test_a_broken_motion_fails_in_one_line(run_dir, tmp_path, capsys, edit, problem):
    broken = _edited(run_dir, tmp_path, edit)
    assert check_cli.main([str(broken)]) == 1
    out = capsys.readouterr().out.strip()
    assert problem in out and "\n" not in out


def test_a_posture_in_the_wall_is_found(run_dir, tmp_path, tank):
    problems = check_motion(read_timed(_edited(run_dir, tmp_path, _into_the_wall)), tank)
    assert any("the backbone moves" in p for p in problems)
    last = len(read_timed(run_dir).dis) - 1
    assert any(p.startswith(f"entry {last} keeps") for p in problems)


def test_unreadable_timing_exits_2(run_dir, tmp_path, capsys):
    def bad(data):
        data["timing"]["velocities"] = [[1e400]]

    assert check_cli.main([str(_edited(run_dir, tmp_path, bad))]) == 2
    err = capsys.readouterr().err.strip()
    assert "timing.velocities" in err and "\n" not in err


def test_an_untimed_motion_is_timed_when_read(run_dir, tmp_path, capsys):
    def untimed(data):
        data.pop("timing")

    # a run saved before the robot extra was installed: timed when read, and said so
    out = tmp_path / "x.json"
    assert export_cli.main([str(_edited(run_dir, tmp_path, untimed)), "-o", str(out)]) == 0
    assert "timed now: the run saved no timing" in capsys.readouterr().out
    times = [p["time_from_start"]["sec"] for p in json.loads(out.read_text())["points"]]
    assert times[-1] == int(read_timed(run_dir).timing.duration)
    with pytest.raises(CheckpointError, match="has no timing"):
        read_timed(tmp_path / "edited")  # no tank to time it in


def test_jointtrajectory_json_matches_the_trajectory(run_dir, tmp_path):
    out = tmp_path / "jt.json"
    assert export_cli.main([str(run_dir), "-o", str(out)]) == 0
    message = json.loads(out.read_text())
    run = read_timed(run_dir)
    assert message["joint_names"][0] == "dis" and len(message["points"]) == len(run.timing.t)
    positions = np.array([p["positions"] for p in message["points"]])
    np.testing.assert_array_equal(positions, joint_positions(run.dis, run.theta, run.phi))
    times = [
        p["time_from_start"]["sec"] + p["time_from_start"]["nanosec"] * 1e-9
        for p in message["points"]
    ]
    np.testing.assert_allclose(times, run.timing.t, atol=1e-9)
    velocities = np.array([p["velocities"] for p in message["points"]])
    tiny = np.finfo(float).tiny  # subnormal residue is written as 0
    expected = np.where(np.abs(run.timing.velocities) < tiny, 0.0, run.timing.velocities)
    np.testing.assert_array_equal(velocities, expected)
    # units said, and no subnormal residue or negative zero written
    assert message["units"]["positions"]["dis"] == "cm"
    assert message["units"]["positions"]["section_1_kx"] == "rad"
    every = np.concatenate([velocities.ravel(), positions.ravel()])
    assert not np.any((every != 0) & (np.abs(every) < np.finfo(float).tiny))
    assert not np.any(np.signbit(every) & (every == 0))
    # the bending vectors give back the postures' angles
    kx, ky = positions[:, 1::2], positions[:, 2::2]
    np.testing.assert_allclose(np.hypot(kx, ky), run.theta, atol=1e-12)


def test_cable_csv_matches_the_cables(run_dir, tmp_path):
    out = tmp_path / "cables.csv"
    assert (
        export_cli.main([str(run_dir), "-o", str(out), "--format", "csv", "--space", "cables"]) == 0
    )
    with out.open() as f:
        rows = list(csv.DictReader(f))
    run = read_timed(run_dir)
    n = run.theta.shape[1]
    assert len(rows) == len(run.timing.t)
    cables = cable_lengths(run.theta, run.phi, run.timing.limits)
    for i in (0, len(rows) // 2, len(rows) - 1):
        assert float(rows[i]["time_s"]) == run.timing.t[i]
        assert float(rows[i]["dis_cm"]) == run.dis[i]
        got = [float(rows[i][f"section_{s + 1}_cable_{j}_cm"]) for s in range(n) for j in range(3)]
        np.testing.assert_allclose(got, cables[i].ravel(), atol=1e-12)
    # the cable rates are the cables' change over time (finite differences, mid-motion)
    mid = len(rows) // 2
    dt = run.timing.t[mid + 1] - run.timing.t[mid - 1]
    name = f"section_{n}_cable_0"
    rate = (float(rows[mid + 1][f"{name}_cm"]) - float(rows[mid - 1][f"{name}_cm"])) / dt
    velocity = float(rows[mid][f"{name}_velocity_cm_per_s"])
    assert math.isclose(velocity, rate, rel_tol=0.1, abs_tol=1e-3)


def test_export_and_check_agree_in_the_library(run_dir, tank):
    run = read_timed(run_dir / "trajectory.json")
    assert check_motion(run, tank) == []
    assert export_motion(run, "csv").count("\n") == len(run.timing.t) + 1


def test_the_check_trusts_the_command_line_not_the_files_margin(run_dir, tmp_path, capsys, tank):
    """A file that states a negative margin for a motion through the wall still fails."""

    def lying(data):
        _into_the_wall(data)
        data["margin_cm"] = -50.0

    broken = _edited(run_dir, tmp_path, lying)
    assert check_cli.main([str(broken)]) == 1
    last = len(read_timed(run_dir).dis) - 1
    problems = check_motion(read_timed(broken), tank)
    assert any(p.startswith(f"entry {last} keeps") and "(margin 1 cm)" in p for p in problems)
    # the margin is the command line's: a planned motion fails a margin it was not planned for
    capsys.readouterr()
    stated = tmp_path / "stated"
    shutil.copytree(run_dir, stated)
    data = json.loads((stated / "trajectory.json").read_text())
    (stated / "trajectory.json").write_text(json.dumps({**data, "margin_cm": -50.0}))
    assert check_cli.main([str(stated), "--margin", "15"]) == 1
    assert "keeps" in capsys.readouterr().out
    # the file's own margin is reported beside the one used, never used
    assert check_cli.main([str(stated)]) == 0
    assert "margin 1 cm; the file states -50 cm" in capsys.readouterr().out
    assert check_cli.main([str(stated), "--margin", "-1"]) == 2


def test_export_writes_only_a_motion_that_passes_the_check(run_dir, tmp_path, capsys):
    broken = _edited(run_dir, tmp_path, _into_the_wall)
    out = tmp_path / "out.json"
    assert export_cli.main([str(broken), "-o", str(out)]) == 1
    assert "not written" in capsys.readouterr().err and not out.exists()
    assert export_cli.main([str(broken), "-o", str(out), "--unchecked"]) == 0
    assert json.loads(out.read_text())["checked_margin_cm"] is None
    csv_out = tmp_path / "out.csv"
    assert export_cli.main([str(broken), "-o", str(csv_out), "--unchecked", "--format", "csv"]) == 0
    assert csv_out.read_text().startswith("# not checked")
    assert export_cli.main([str(run_dir), "-o", str(out)]) == 0
    assert json.loads(out.read_text())["checked_margin_cm"] == 1.0


def test_export_never_writes_over_its_input_or_a_device(run_dir, tmp_path, capsys):
    before = (run_dir / "trajectory.json").read_bytes()
    for target in (run_dir / "trajectory.json", "/dev/full", tmp_path):
        assert export_cli.main([str(run_dir), "-o", str(target)]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and ("input of this command" in err or "not a regular" in err)
    assert (run_dir / "trajectory.json").read_bytes() == before
    assert Path("/dev/full").is_char_device()


@pytest.mark.parametrize(
    "motion, problem",
    [
        ([{"dis": 0.0, "theta": [0.0] * 100_000, "phi": [0.0] * 100_000}], "at most 64"),
        ([{"dis": 10**400, "theta": [0.1], "phi": [0.0]}], "must be numbers"),
    ],
)
def test_readers_refuse_what_no_arm_means_in_one_line(tmp_path, capsys, motion, problem):
    """100,000 sections or a number beyond a float: one line, exit 2, nothing allocated."""
    run = tmp_path / "hostile"
    run.mkdir()
    data = {"motion": motion, "section_length": 50.0, "margin_cm": 10**400}
    (run / "trajectory.json").write_text(json.dumps(data))
    for main in (check_cli.main, lambda a: export_cli.main([*a, "-o", str(tmp_path / "x")])):
        assert main([str(run)]) == 2
        err = capsys.readouterr().err.strip()
        assert problem in err and "\n" not in err


def test_check_takes_several_runs_and_export_says_it_takes_one(run_dir, tmp_path, capsys):
    broken = _edited(run_dir, tmp_path, _faster)
    assert check_cli.main([str(run_dir), str(run_dir)]) == 0
    assert capsys.readouterr().out.count(": ok (") == 2
    assert check_cli.main([str(run_dir), str(broken), str(tmp_path / "missing")]) == 2
    captured = capsys.readouterr()
    assert captured.out.count("\n") == 2 and "times its speed limit" in captured.out
    assert captured.err.count("\n") == 1
    # several runs go to a folder, one file each; the one that fails its check is not written
    folder = tmp_path / "deploy"
    assert export_cli.main([str(run_dir), str(broken), "-o", str(folder)]) == 1
    assert sorted(p.name for p in folder.iterdir()) == [f"{run_dir.name}.json"]
    assert "not written" in capsys.readouterr().err
