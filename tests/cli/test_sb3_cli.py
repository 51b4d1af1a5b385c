"""``aftir train ALGO --env ID``: steps said as trained, overrides checked before training."""

from __future__ import annotations

import pytest

from aftir_rl.cli import train
from aftir_rl.core.errors import ConfigError
from aftir_rl.rl.sb3 import load_sb3_config
from aftir_rl.rl.sb3.config import rollout_steps


def test_steps_below_a_rollout_are_said(tmp_path, capsys):
    assert rollout_steps("ppo", load_sb3_config("ppo_ftl", "ppo")) == 128 * 128
    args = ["ppo", "--env", "AFTIR-ArmReach-v0", "--hyperparams", "n_steps:64", "batch_size:64"]
    args += ["--eval-episodes", "1", "--logdir", str(tmp_path), "--no-progress"]
    assert train.main([*args, "--total-timesteps", "100"]) == 0
    assert "so 128 steps are trained for --total-timesteps 100" in capsys.readouterr().out
    assert train.main([*args, "--total-timesteps", "0"]) == 0
    assert "note:" not in capsys.readouterr().out


@pytest.mark.parametrize(
    "extra, says",
    [
        (["--env-kwargs", "nope:1"], "unknown key 'nope'"),
        (["--hyperparams", "n_epochs:0"], "n_epochs"),
        (["--env-kwargs", "bay"], "KEY:VALUE"),
        (["--env-kwargs", "tank:wing:3:1"], "a config names no tank; give --tank"),
        (["--tank", "nope"], "unknown tank 'nope'"),
        (["--tank", "wing:3:9-1"], "1 to 64 seeds"),
        (["--tank", "wing:3:1", "--env", "AFTIR-ArmFull-v0"], "only AFTIR-ArmFTL-v0 takes a tank"),
    ],
)
def test_bad_overrides_are_one_line_before_training(extra, says, tmp_path, capsys):
    args = ["ppo", "--env", "AFTIR-ArmFTL-v0", "--logdir", str(tmp_path), *extra]
    assert train.main(args) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and "\n" not in err
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_tank_option_reaches_every_stage_and_files_name_none(tmp_path):
    args = train.build_parser().parse_args(
        ["ppo", "--config", "ppo_ftl_curriculum", "--tank", "wing:3:0-7"]
    )
    configs = train._train_config(args).stages
    assert len(configs) == 2 and all(c.env_kwargs["tank"] == "wing:3:0-7" for c in configs)
    shared = tmp_path / "tank.yaml"
    shared.write_text("env_id: AFTIR-ArmFTL-v0\nenv_kwargs:\n  tank: /etc/passwd\n")
    with pytest.raises(ConfigError, match="a config names no tank"):
        load_sb3_config(shared, "ppo")


@pytest.mark.slow
def test_training_that_diverges_keeps_the_run_and_says_so(tmp_path, capsys):
    """learning_rate 10 makes PPO's weights NaN: one line, exit 2, the logs kept."""
    from aftir_rl.cli import train

    argv = ["ppo", "--env", "AFTIR-ArmReach-v0", "--hyperparams", "learning_rate:10",
            "max_grad_norm:1e9", "--total-timesteps", "8192", "--logdir", str(tmp_path),
            "--no-progress"]  # fmt: skip
    assert train.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "training diverged at step" in err and "\n" not in err
    (kept,) = tmp_path.iterdir()
    assert kept.name.endswith(".partial") and (kept / "diverged.json").is_file()
    assert any(p.name.startswith("events.out.tfevents") for p in kept.rglob("*"))


@pytest.mark.parametrize(("algo", "steps", "shown"), [("ppo", 100, 128), ("sac", 101, 102)])
def test_the_progress_bar_counts_to_the_steps_really_taken(algo, steps, shown):
    """PPO collects whole rollouts (2 envs x 32 steps: 100 asked, 128 taken); SAC steps 2 envs."""
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.env_util import make_vec_env

    from aftir_rl.rl.sb3.train import _ProgressBar

    venv = make_vec_env("Pendulum-v1", n_envs=2, seed=0)
    if algo == "ppo":
        model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, seed=0)
    else:
        model = SAC("MlpPolicy", venv, learning_starts=200, seed=0)
    bar = _ProgressBar()
    model.learn(steps, callback=bar)
    assert model.num_timesteps == shown
    assert bar.pbar.total == shown and bar.pbar.n == shown
