"""``aftir train ALGO --env ID``: the shipped config for the env, and steps said as trained."""

from __future__ import annotations

import dataclasses

import pytest

from aftir_rl.cli import train
from aftir_rl.core.errors import ConfigError
from aftir_rl.rl.sb3 import load_sb3_config
from aftir_rl.rl.sb3.config import ENV_CONFIGS, env_config_name, rollout_steps


@pytest.mark.parametrize(
    "algo, env_id", [(a, e) for a, table in ENV_CONFIGS.items() for e in table]
)
def test_each_env_gets_a_shipped_config_made_for_it(algo, env_id):
    config = load_sb3_config(env_config_name(algo, f"aftir_rl:{env_id}"), algo)
    assert config.env_id == env_id
    if env_id == "AFTIR-ArmFTL-v0" and algo == "ppo":
        assert config.policy == "MultiInputPolicy"  # the Dict observation


def test_an_env_without_a_shipped_config_is_one_line(capsys):
    assert train.main(["sac", "--env", "AFTIR-ArmFull-v0"]) == 2
    err = capsys.readouterr().err.strip()
    assert "no shipped sac config for AFTIR-ArmFull-v0" in err and "\n" not in err
    with pytest.raises(ConfigError, match="ppo cannot train on 'CartPole-v1'; use one of"):
        env_config_name("ppo", "CartPole-v1")


def test_steps_below_a_rollout_are_said(capsys):
    config = load_sb3_config("ppo_ftl", "ppo")
    assert rollout_steps("ppo", config) == 128 * 128
    train._say_rollout("ppo", dataclasses.replace(config, total_timesteps=4096))
    assert "so 16,384 steps are trained for --total-timesteps 4,096" in capsys.readouterr().out
    train._say_rollout("ppo", dataclasses.replace(config, total_timesteps=2 * 16_384))
    assert capsys.readouterr().out == ""


@pytest.mark.parametrize(
    "extra, says",
    [
        (["--env-kwargs", "nope:1"], "unknown key 'nope'"),
        (["--hyperparams", "n_epochs:0"], "n_epochs"),
        (["--env-kwargs", "bay"], "KEY:VALUE"),
    ],
)
def test_bad_overrides_are_one_line_before_training(extra, says, tmp_path, capsys):
    args = ["ppo", "--env", "AFTIR-ArmFTL-v0", "--logdir", str(tmp_path), *extra]
    assert train.main(args) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and "\n" not in err
    assert list(tmp_path.iterdir()) == []  # nothing written
