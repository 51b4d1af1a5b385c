from __future__ import annotations

import json
import subprocess
import sys

import pytest

from aftir_rl.cli import evaluate, rollout, train
from aftir_rl.core.errors import ConfigError
from aftir_rl.experiments.runs import evaluate_run
from aftir_rl.rl.pretrained import load, policy_dir


@pytest.mark.slow
def test_compare_q_table_and_ppo_runs(tmp_path, capsys):
    runs = tmp_path / "runs"
    assert (
        train.main(
            ["q_table", "--target", "230", "72", "10", "--logdir", str(runs), "--no-progress"]
        )
        == 0
    )
    config = tmp_path / "ppo.yaml"
    config.write_text(
        "env_id: AFTIR-ArmReach-v0\neval_freq: 100000\neval_targets: 2\ncheckpoint_freq: 1000\n"
        "hyperparameters:\n  n_steps: 128\n  batch_size: 64\n"
    )
    assert (
        train.main(
            [
                "ppo",
                "--config",
                str(config),
                "--total-timesteps",
                "128",
                "--logdir",
                str(runs),
                "--no-progress",
            ]
        )
        == 0
    )
    capsys.readouterr()
    dirs = sorted(str(p) for p in runs.iterdir())
    assert evaluate.main([*dirs, "--logdir", str(tmp_path / "eval")]) == 0
    out = capsys.readouterr().out
    assert "q_table + FTL motion" in out and "ppo (AFTIR-ArmReach-v0)" in out
    # Success for a Q-table run: a complete follow-the-leader motion keeping the 1 cm margin;
    # evaluation plans it again from the greedy path, and finds what training wrote.
    row = next(line for line in out.splitlines() if "q_table + FTL motion" in line)
    (q_dir,) = [p for p in runs.iterdir() if p.name.startswith("q_table")]
    trajectory = json.loads((q_dir / "trajectory.json").read_text())
    assert trajectory["complete"] and "| 1 | 100% |" in row
    # a Q-table run is greedy: sampling it is refused in one line, nothing logged
    q_run = str(q_dir)
    assert evaluate.main([q_run, "--stochastic", "--logdir", str(tmp_path / "no")]) == 2
    assert "error: --stochastic: seed 0: " in capsys.readouterr().err
    assert evaluate.main([q_run, "--tank", "open_space", "--logdir", str(tmp_path / "no")]) == 2
    assert "error: --tank: open_space: " in capsys.readouterr().err
    # the library says what is wrong with the value; the flag is the command line's word
    with pytest.raises(ConfigError, match="evaluated greedily") as refused:
        evaluate_run(q_run, policy_seed=0)
    assert refused.value.param == "policy_seed" and "--" not in str(refused.value)
    assert not list((tmp_path / "no").glob("evaluate__*"))
    clearance = float(row.split("|")[7])
    assert clearance == pytest.approx(trajectory["min_clearance_cm"], abs=0.01) and clearance >= 1
    (logged,) = [p for p in (tmp_path / "eval").iterdir() if p.name.startswith("evaluate__")]
    # one folder per run, the same eval/* tags: TensorBoard overlays the runs on one card
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    rows = json.loads((logged / "results.json").read_text())
    assert set(rows) == {p.name for p in logged.iterdir() if p.is_dir()} and len(rows) == 2
    for name, r in rows.items():
        events = EventAccumulator(str(logged / name))
        events.Reload()
        assert "eval/success_rate" in events.Tags()["scalars"]
        assert events.Scalars("eval/success_rate")[0].value == pytest.approx(r["success_rate"])


def test_not_a_run_dir_exits_2(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "aftir_rl.evaluate", str(tmp_path)], capture_output=True, text=True
    )
    assert proc.returncode == 2 and "not a run directory" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_stochastic_evaluation_samples_the_policy_reproducibly(tmp_path, capsys):
    """``--stochastic SEED``: episode ``i`` samples with torch seeded ``SEED + i``, as by hand."""
    import gymnasium as gym
    import numpy as np
    import torch

    from aftir_rl.experiments.runs import evaluate_run
    from aftir_rl.rl.sb3.evaluation import evaluation_targets

    name, draw = "ppo-armftl-bay2", (3, 4_200_000)
    run = policy_dir(name)
    sampled = evaluate_run(run, draw=draw, policy_seed=11)
    again = evaluate_run(run, draw=draw, policy_seed=11)
    mean = evaluate_run(run, draw=draw)
    for key in ("success_rate", "tip_error_cm", "path_length_cm", "min_clearance_cm"):
        assert sampled[key] == again[key]
    assert sampled["path_length_cm"] != mean["path_length_cm"]  # not the mean action
    assert "sampled from seed 11" in sampled["agent"]
    # the same three episodes by hand: torch seeded 11 + i, the policy's own sampling
    model, env_id, kwargs = load(name)
    env = gym.make(env_id, **kwargs)
    errors = []
    for i, target in enumerate(evaluation_targets(env_id, *draw, env_kwargs=kwargs)):
        torch.manual_seed(11 + i)
        obs, _ = env.reset(options={"target": target})
        done = False
        while not done:
            action, _ = model.predict(obs, deterministic=False)
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        errors.append(info["distance_cm"])
    assert sampled["tip_error_cm"] == pytest.approx(np.mean(errors), rel=1e-12)
    # aftir rollout --stochastic 11: the same episodes, written as motions
    out = tmp_path / "motions"
    argv = ["--pretrained", name, "--random", "3", "--seed", str(draw[1]), "--stochastic", "11"]
    assert rollout.main([*argv, "-o", str(out)]) == 0
    summaries = [json.loads(p.read_text()) for p in out.glob("*/summary.json")]
    rolled = [s["tip_error_cm"] for s in summaries]
    assert sorted(rolled) == pytest.approx(sorted(errors), rel=1e-12)
    assert sorted(s["policy_seed"] for s in summaries) == [11, 12, 13]
    assert all(s["method"] == "policy (PPO, sampled)" for s in summaries)
    assert evaluate.main([str(run), "--stochastic", "-3"]) == 2
    assert "--stochastic must be from 0" in capsys.readouterr().err
