from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from aftir_rl.cli import train
from aftir_rl.core.robot import tip_position
from aftir_rl.rl.tabular import QLearning, greedy_rollout


def _events(run_dir: Path) -> EventAccumulator:
    acc = EventAccumulator(str(run_dir), size_guidance={"images": 0, "tensors": 0, "scalars": 0})
    acc.Reload()
    return acc


def test_q_table_run_writes_everything(tmp_path, capsys):
    rc = train.main(
        [
            "q_table",
            "--target",
            "230",
            "140",
            "90",
            "--logdir",
            str(tmp_path),
            "--no-progress",
            "--seed",
            "3",
        ]
    )
    assert rc == 0
    out = capsys.readouterr().out
    assert "BFS optimum 22 (optimal)" in out
    (run_dir,) = list(tmp_path.iterdir())
    assert run_dir.name.startswith("q_table__AFTIR-Tank-v0__230_140_90__3__")
    assert sorted(p.name for p in run_dir.iterdir() if not p.name.startswith("events")) == [
        "path.json",
        "progress.csv",
        "q_table.npz",
        "trajectory.json",
    ]
    path = json.loads((run_dir / "path.json").read_text())
    assert path["target"] == [230, 140, 90]
    assert path["cells"][0] == [3, 2, 0] and path["cells"][-1] == [14, 9, 4]
    assert len(path["cells"]) == len(path["points_cm"]) == 23
    assert path["points_cm"][0] == [10, 0, 10]  # centre of the start cell
    acc = _events(run_dir)
    tags = acc.Tags()
    for tag in (
        "rollout/ep_rew_mean",
        "rollout/ep_len_mean",
        "eval/success_rate",
        "eval/tip_error_cm",
        "eval/collision_rate",
        "eval/path_length_cm",
        "eval/min_clearance_cm",
    ):
        assert tag in tags["scalars"], tag
    # the same meaning as in SB3 runs: the arm's tip, along the whole motion
    assert acc.Scalars("eval/success_rate")[-1].value == 1.0
    assert acc.Scalars("eval/collision_rate")[-1].value == 0.0
    assert acc.Scalars("eval/tip_error_cm")[-1].value < 0.01
    assert acc.Scalars("eval/min_clearance_cm")[-1].value >= 1.0
    assert acc.Scalars("eval/path_length_cm")[-1].value > 300
    assert "paths/230_140_90" in tags["images"] and "paths/eval" in tags["images"]
    image = acc.Images("paths/eval")[-1]
    assert image.width > 100 and image.height > 100
    assert any(t.startswith("hyperparameters") for t in tags["tensors"])
    # trajectory.json: the follow-the-leader motion contract (checked in depth by test_ftl)
    trajectory = json.loads((run_dir / "trajectory.json").read_text())
    assert trajectory["complete"] and trajectory["method"] == "ftl"
    assert trajectory["margin_cm"] == 1.0 and trajectory["section_length"] == 50.0
    assert len(trajectory["waypoint_index"]) == len(path["cells"])
    last = trajectory["motion"][-1]
    tip = tip_position(last["dis"], last["theta"], last["phi"], 50.0)
    assert np.linalg.norm(tip - np.array([230, 140, 90])) < 0.01
    assert trajectory["ftl_deviation_cm"]["max"] >= trajectory["ftl_deviation_cm"]["mean"] > 0
    # The checkpoint loads and its greedy policy is the logged path.
    env = gym.make("AFTIR-Tank-v0", target=(230, 140, 90))
    agent = QLearning.load(run_dir / "q_table.npz", env)
    assert agent.metadata["target_cell"] == [14, 9, 4]
    states, reached = greedy_rollout(agent, env)
    assert reached and [list(env.unwrapped.raster.cell(s)) for s in states] == path["cells"]


def _train_one(logdir: Path, *args: str) -> Path:
    """Train on (-50, 72, 90) into ``logdir`` and return the run directory."""
    argv = [
        "q_table",
        "--target",
        "-50",
        "72",
        "90",
        "--logdir",
        str(logdir),
        "--no-progress",
        "--no-postures",
    ]
    assert train.main([*argv, *args]) == 0
    (run_dir,) = list(logdir.iterdir())
    return run_dir


def test_resume(tmp_path):
    first = _train_one(tmp_path / "a", "--episodes", "300")
    second = _train_one(tmp_path / "b", "--episodes", "1700", "--resume", str(first))
    assert json.loads((second / "path.json").read_text())["episodes"] == 2000
    # Resumed 300 + 1700 is the same table as 2000 straight.
    straight = _train_one(tmp_path / "c")
    np.testing.assert_array_equal(
        QLearning.read_checkpoint(second / "q_table.npz")[0],
        QLearning.read_checkpoint(straight / "q_table.npz")[0],
    )


@pytest.mark.parametrize(
    "args, message",
    [
        # a subprocess that builds the tank first: the fast tier keeps the other four
        pytest.param(["--target", "0", "60", "50"], "obstructed cell", marks=pytest.mark.slow),
        (["--target", "999", "0", "10"], "outside the tank box"),
        (["--config", "nope.yaml"], "no shipped config of that name"),
        (["--episodes", "0"], "--episodes must be from 1 to"),
        (["--bridge-seconds", "-1"], "--bridge-seconds must be from 0 to 3600"),
        (["--bridge-seconds", "1e308"], "--bridge-seconds must be from 0 to 3600"),
    ],
)
def test_user_errors_exit_2_without_traceback(tmp_path, args, message):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "aftir_rl.train",
            "q_table",
            "--logdir",
            str(tmp_path / "runs"),
            "--no-progress",
            *args,
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


def test_bad_config_and_corrupt_resume(tmp_path, capsys):
    cfg = tmp_path / "q.yaml"
    cfg.write_text("episodes: 10\nlearning_rat: 0.5\n")
    assert train.main(["q_table", "--config", str(cfg), "--logdir", str(tmp_path)]) == 2
    assert "unknown key 'learning_rat'" in capsys.readouterr().err
    cfg.write_text("episodes: ten\n")
    assert train.main(["q_table", "--config", str(cfg), "--logdir", str(tmp_path)]) == 2
    assert "episodes: expected an integer" in capsys.readouterr().err
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"\x00" * 100)
    assert (
        train.main(
            [
                "q_table",
                "--target",
                "230",
                "72",
                "10",
                "--resume",
                str(bad),
                "--logdir",
                str(tmp_path / "runs"),
            ]
        )
        == 2
    )
    assert "not a readable Q-table checkpoint" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


def test_help():
    proc = subprocess.run(
        [sys.executable, "-m", "aftir_rl.train", "q_table", "--help"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0 and "--target X Y Z" in proc.stdout and "--resume" in proc.stdout


def test_all_targets_run(tmp_path, capsys):
    assert (
        train.main(
            [
                "q_table",
                "--all-targets",
                "--logdir",
                str(tmp_path),
                "--no-progress",
                "--episodes",
                "1500",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    (run_dir,) = list(tmp_path.iterdir())
    assert run_dir.name.startswith("q_table_goal__AFTIR-TankGoal-v0__all__0__")
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["n_goals"] == summary["n_reached"] == 586
    assert f"BFS-optimal for {summary['n_optimal']}" in out
    acc = _events(run_dir)
    assert "eval/success_rate" in acc.Tags()["scalars"]
    assert train.main(["q_table", "--all-targets", "--target", "1", "2", "3"]) == 2


def test_linear_learning_rate_falls_to_zero_over_a_learn_call(tmp_path):
    """``learning_rate: lin_X`` (RL Zoo's form): X at the start of a run, 0 at its end."""
    from aftir_rl.rl.sb3 import load_model
    from aftir_rl.rl.sb3.config import SB3Config, build_model, check_sb3_config

    hyper = {"learning_rate": "lin_1e-3", "n_steps": 64, "batch_size": 64, "n_epochs": 1}
    config = SB3Config(env_id="AFTIR-ArmReach-v0", n_envs=1, hyperparameters=hyper)
    check_sb3_config(config, "ppo", "test")
    model = build_model("ppo", config, gym.make("AFTIR-ArmReach-v0"))
    assert model.lr_schedule(1.0) == pytest.approx(1e-3)
    assert model.lr_schedule(0.25) == pytest.approx(2.5e-4)
    model.learn(128)  # two rollouts: the updates run at progress 0.5, then 0
    assert model.policy.optimizer.param_groups[0]["lr"] == pytest.approx(0.0)
    # resumed (--resume): SB3 counts the progress over all of the model's steps, so the resumed
    # stage starts at 1e-3 * (1 - 192/256) after its first rollout and still ends at 0
    rates, update = [], model.train

    def recording_update() -> None:
        update()
        rates.append(model.policy.optimizer.param_groups[0]["lr"])

    model.train = recording_update  # type: ignore[method-assign]
    model.learn(128, reset_num_timesteps=False)
    assert rates == pytest.approx([2.5e-4, 0.0])
    del model.train
    assert config.hyperparameters["learning_rate"] == "lin_1e-3"  # config.json keeps the text
    # what SB3 saves of the schedule is a class the safe loader knows, not a pickled function
    model.save(tmp_path / "model.zip")
    loaded = load_model("ppo", tmp_path / "model.zip", config=config)
    assert loaded.lr_schedule(0.5) == pytest.approx(5e-4)
