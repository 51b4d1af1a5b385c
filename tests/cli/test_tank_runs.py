"""PPO across a pool of generated tanks from the command line, evaluated in tanks never seen."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aftir_rl.cli import evaluate, rollout, train
from aftir_rl.core.tank import load_tank

POOL_YAML = (
    "env_id: AFTIR-ArmFTL-v0\nn_envs: 6\neval_freq: 100000\neval_targets: 4\n"
    "checkpoint_freq: 100000\npolicy: MultiInputPolicy\nenv_kwargs:\n  guide: true\n"
    "hyperparameters:\n  n_steps: 16\n  batch_size: 48\n  n_epochs: 1\n"
    "  policy_kwargs:\n    net_arch: [16]\n"
)


@pytest.mark.slow  # about 40 s: builds five generated tanks twice (training, evaluation)
def test_train_on_a_pool_then_evaluate_in_held_out_tanks(tmp_path, capsys):
    (tmp_path / "pool.yaml").write_text(POOL_YAML)
    argv = ["ppo", "--config", str(tmp_path / "pool.yaml"), "--total-timesteps", "96"]
    argv += ["--tank", "wing:2:0-2", "--logdir", str(tmp_path / "runs"), "--no-progress"]
    assert train.main(argv) == 0
    run = next((tmp_path / "runs").iterdir())
    config = json.loads((run / "config.json").read_text())
    assert config["env_kwargs"]["tank"] == "wing:2:0-2"  # the run records its pool
    summary = json.loads((run / "summary.json").read_text())
    assert 0.0 <= summary["success_rate"] <= 1.0 and summary["tip_error_cm"] > 0
    capsys.readouterr()
    out = tmp_path / "eval"
    argv = [str(run), "--tank", "wing:2:7-8", "--random", "4", "--logdir", str(out)]
    assert evaluate.main(argv) == 0
    table = capsys.readouterr().out
    assert "| 4 |" in table
    # the held-out targets lie in the tanks 7, 8, 7, 8 of the pool
    from aftir_rl.rl.sb3.evaluation import evaluation_targets

    drawn = evaluation_targets("AFTIR-ArmFTL-v0", 4, 1_000_000, {"tank": "wing:2:7-8"})
    for i, target in enumerate(drawn):
        assert load_tank(f"wing:2:{7 + i % 2}").distance(np.asarray(target)) >= 5.0
    # a motion is in one tank: a pool run rolls out with --tank
    moves = tmp_path / "moves"
    assert rollout.main([str(run), "--random", "1", "-o", str(moves)]) == 2
    assert "give --tank" in capsys.readouterr().err
    argv = [str(run), "--random", "1", "--tank", "wing:2:8", "-o", str(moves)]
    assert rollout.main(argv) == 0
    (folder,) = moves.iterdir()
    assert json.loads((folder / "summary.json").read_text())["tank"] == "wing:2:8"


@pytest.mark.slow  # about 8 s: a few wings built for training, two for the evaluation
def test_train_on_a_stream_then_evaluate_on_its_first_wings(tmp_path, capsys):
    (tmp_path / "pool.yaml").write_text(POOL_YAML)
    argv = ["ppo", "--config", str(tmp_path / "pool.yaml"), "--total-timesteps", "256"]
    argv += ["--tank", "wing:2:60+", "--env-kwargs", "tank_episodes:2", "tanks_at_once:2"]
    argv += ["--logdir", str(tmp_path / "runs"), "--no-progress"]
    assert train.main(argv) == 0
    run = next((tmp_path / "runs").iterdir())
    kwargs = json.loads((run / "config.json").read_text())["env_kwargs"]
    assert kwargs["tank"] == "wing:2:60+" and kwargs["tank_episodes"] == 2
    capsys.readouterr()
    assert evaluate.main([str(run), "--random", "2", "--logdir", str(tmp_path / "eval")]) == 0
    assert "| 2 |" in capsys.readouterr().out
    # a motion is in one tank: a stream run rolls out with --tank, as a pool run does
    assert rollout.main([str(run), "--random", "1", "-o", str(tmp_path / "moves")]) == 2
    assert "stream of tanks wing:2:60+" in capsys.readouterr().err
