"""Hyperparameters keyed by env id (RL Zoo's format), and the named configs over them."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from aftir_rl.cli import train
from aftir_rl.core.config import CONFIG_DIR
from aftir_rl.core.errors import ConfigError
from aftir_rl.rl.sb3 import entry_config, load_sb3_config
from aftir_rl.rl.sb3.config import HER_KWARGS, SB3_ENV_IDS
from aftir_rl.rl.sb3.hyperparams import (
    entry_env_ids,
    is_curriculum,
    is_hyperparams_file,
    load_curriculum,
)

ROOT = Path(__file__).resolve().parents[2]
ALGOS = ("ppo", "sac", "td3")


@pytest.mark.parametrize("algo", ALGOS)
def test_each_entry_is_the_file_read_plainly(algo):
    raw = yaml.safe_load((CONFIG_DIR / "hyperparams" / f"{algo}.yml").read_text())
    assert set(entry_env_ids(algo)) == set(raw) and set(raw) <= set(SB3_ENV_IDS)
    for env_id, entry in raw.items():
        config = entry_config(algo, f"aftir_rl:{env_id}")  # the prefixed id names it too
        assert config.total_timesteps == entry["n_timesteps"]
        assert config.policy == entry["policy"] and config.n_envs == entry.get("n_envs", 1)
        assert config.env_kwargs == entry.get("env_kwargs", {})
        assert config.her == ("replay_buffer_class" in entry)
        zoo = {"n_timesteps", "policy", "n_envs", "env_kwargs"}
        zoo |= {"replay_buffer_class", "replay_buffer_kwargs"}
        assert config.hyperparameters == {k: v for k, v in entry.items() if k not in zoo}
        assert config.eval_freq == max(10_000, config.total_timesteps // 20)
        assert config.checkpoint_freq == max(50_000, config.total_timesteps // 10)


def test_the_ftl_entries_observe_a_dict_and_her_relabels():
    assert entry_config("ppo", "AFTIR-ArmFTL-v0").policy == "MultiInputPolicy"
    for algo in ("sac", "td3"):
        raw = yaml.safe_load((CONFIG_DIR / "hyperparams" / f"{algo}.yml").read_text())
        assert raw["AFTIR-ArmFTL-v0"]["replay_buffer_kwargs"] == HER_KWARGS
        assert entry_config(algo, "AFTIR-ArmFTL-v0").her


def test_an_env_without_an_entry_is_one_line(capsys):
    assert train.main(["sac", "--env", "AFTIR-ArmFull-v0"]) == 2
    err = capsys.readouterr().err.strip()
    assert "no sac hyperparameters for AFTIR-ArmFull-v0" in err and "\n" not in err
    assert "AFTIR-ArmFTL-v0" in err  # names those that have one
    with pytest.raises(ConfigError, match="ppo cannot train on 'CartPole-v1'; use one of"):
        entry_config("ppo", "CartPole-v1")


def _write(tmp_path, data, name="c.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return path


def test_a_named_config_states_only_what_differs(tmp_path):
    base = entry_config("ppo", "AFTIR-ArmFTL-v0")
    path = _write(
        tmp_path,
        {
            "env_id": "AFTIR-ArmFTL-v0",
            "total_timesteps": 4_000_000,
            "eval_targets": 7,
            "env_kwargs": {"bay": 1},
            "hyperparameters": {"learning_rate": "1e-4"},
        },
    )
    config = load_sb3_config(path, "ppo")
    assert config.hyperparameters == {**base.hyperparameters, "learning_rate": 1e-4}
    assert config.env_kwargs == {**base.env_kwargs, "bay": 1}
    assert (config.policy, config.n_envs, config.eval_targets) == ("MultiInputPolicy", 128, 7)
    assert (config.eval_freq, config.checkpoint_freq) == (200_000, 400_000)  # of 4M, not 20M
    given = load_sb3_config(_write(tmp_path, {"env_id": "AFTIR-ArmFTL-v0", "eval_freq": 5}), "ppo")
    assert given.eval_freq == 5 and given.checkpoint_freq == base.checkpoint_freq
    assert load_sb3_config(_write(tmp_path, {}), "ppo") == entry_config("ppo", "AFTIR-ArmReach-v0")


def test_shipped_configs_repeat_no_hyperparameter_block():
    """Named configs (shipped and experiments) give only the keys that differ from the entry."""
    paths = [*CONFIG_DIR.glob("*.yaml"), *(ROOT / "experiments" / "configs").glob("*.yaml")]
    assert len(paths) >= 10
    for path in paths:
        if path.stem == "q_table" or is_curriculum(path):
            continue
        config = load_sb3_config(path, "ppo")  # every one still loads
        entry = entry_config("ppo", config.env_id)
        stated = yaml.safe_load(path.read_text()).get("hyperparameters") or {}
        for key in stated:
            assert entry.hyperparameters.get(key) != config.hyperparameters[key], (path, key)


def test_the_recipe_is_the_bay1_config_then_an_inline_bay2_stage():
    bay1, bay2 = load_curriculum("ppo_ftl_curriculum", "ppo")
    assert bay1 == load_sb3_config("ppo_ftl_cost_bay1", "ppo")
    assert bay2.hyperparameters["learning_rate"] == "lin_3e-4"
    assert bay2.hyperparameters["n_steps"] == 128  # the rest from the entry


@pytest.mark.parametrize(
    "entry, says",
    [
        ({"policy_kwargs": "dict(net_arch=[64, 64])"}, "policy_kwargs"),  # never evaluated
        ({"replay_buffer_class": "__import__('os').system('true')"}, "only HerReplayBuffer"),
        ({"replay_buffer_class": "HerReplayBuffer"}, "her: only SAC and TD3"),
        ({"normalize": True}, "unknown key 'normalize'"),
        ({"n_envs": 0}, "n_envs"),
        ({"n_timesteps": 2.5}, "total_timesteps"),
        ({"env_kwargs": {"bay": "x"}}, "bay"),
    ],
)
def test_hostile_entries_are_one_line(tmp_path, entry, says):
    good = {"n_timesteps": 1000, "policy": "MultiInputPolicy"}
    path = _write(tmp_path, {"AFTIR-ArmFTL-v0": {**good, **entry}}, "zoo.yml")
    assert is_hyperparams_file(path)
    with pytest.raises(ConfigError, match=says) as info:
        entry_config("ppo", "AFTIR-ArmFTL-v0", path)
    assert "\n" not in str(info.value)


def test_an_rl_zoo_file_of_your_own_trains_with_env(tmp_path, capsys):
    entry = {"n_timesteps": 64, "policy": "MlpPolicy", "n_steps": 32, "batch_size": 32}
    path = _write(tmp_path, {"AFTIR-ArmReach-v0": entry, "CartPole-v1": entry}, "zoo.yml")
    args = ["ppo", "--config", str(path), "--env", "AFTIR-ArmReach-v0", "--eval-episodes", "1"]
    assert train.main([*args, "--logdir", str(tmp_path / "runs"), "--no-progress"]) == 0
    assert "PPO on AFTIR-ArmReach-v0: 64 steps" in capsys.readouterr().out
    assert train.main(["ppo", "--config", str(path), "--env", "AFTIR-Arm-v0"]) == 2
    assert "no ppo hyperparameters for AFTIR-Arm-v0" in capsys.readouterr().err


def test_the_command_line_numbers_override_the_entry():
    args = train.build_parser().parse_args(
        ["ppo", "--env", "AFTIR-ArmFTL-v0", "--eval-freq", "3", "--eval-episodes", "4"]
        + ["--save-freq", "5", "--total-timesteps", "6"]
    )
    (config,) = train._train_config(args).stages
    expected = dataclasses.replace(
        entry_config("ppo", "AFTIR-ArmFTL-v0"),
        eval_freq=3,
        eval_targets=4,
        checkpoint_freq=5,
        total_timesteps=6,
    )
    assert config == expected


@pytest.mark.slow
@pytest.mark.parametrize(
    "algo, params",
    [
        ("ppo", ["n_envs:2", "n_steps:256", "batch_size:64"]),
        ("sac", ["learning_starts:320", "batch_size:32", "buffer_size:2000"]),  # > 300 steps
    ],
)
def test_rl_zoo_trains_from_the_shipped_file(tmp_path, algo, params):
    """RL Zoo's own train script reads configs/hyperparams/ALGO.yml (the FTL entry, HER too)."""
    pytest.importorskip("rl_zoo3")
    command = [sys.executable, "-m", "rl_zoo3.train", "--algo", algo, "--env", "AFTIR-ArmFTL-v0"]
    command += [
        "--gym-packages",
        "aftir_rl",
        "-conf",
        str(CONFIG_DIR / "hyperparams" / f"{algo}.yml"),
    ]
    command += ["-n", "512", "--eval-freq", "-1", "--seed", "0", "--log-folder", str(tmp_path)]
    done = subprocess.run(
        [*command, "-params", *params], capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    run = tmp_path / algo / "AFTIR-ArmFTL-v0_1"
    assert "MultiInputPolicy" in (run / "AFTIR-ArmFTL-v0" / "config.yml").read_text()
    assert (run / "AFTIR-ArmFTL-v0.zip").is_file()


def test_a_refused_value_names_the_source_that_gave_it(tmp_path):
    """Each stage is checked once, merged; the message names the file or option of the value."""
    from aftir_rl.rl.sb3 import train_config

    named = _write(tmp_path, {"env_id": "AFTIR-ArmFTL-v0", "hyperparameters": {"gamma": 2}})
    cases = [
        ({"config": str(named)}, f"{named}: hyperparameters.gamma"),
        ({"env": "AFTIR-ArmReach-v0", "hyperparams": ["n_epochs:0"]}, "--hyperparams: hyper"),
        ({"env": "AFTIR-ArmReach-v0", "numbers": {"n_envs": 100}}, "--n-envs: n_envs"),
        ({"env": "AFTIR-ArmReach-v0", "env_kwargs": ["bay:1"]}, "--env-kwargs: env_kwargs"),
        # ppo_ftl's env replaced: the FTL entry's 128 envs are too many processes for Reach
        ({"config": "ppo_ftl", "env": "AFTIR-ArmReach-v0"}, "/ppo.yml: AFTIR-ArmFTL-v0: n_envs"),
    ]
    for kwargs, says in cases:
        with pytest.raises(ConfigError) as info:
            train_config("ppo", **kwargs)
        assert says in str(info.value), info.value
    stages = _write(tmp_path, "stages:\n  - config: ppo_ftl\n    env_kwargs: {bay: x}\n")
    with pytest.raises(ConfigError, match=r"stages\[0\]: env_kwargs.bay: unexpected value"):
        load_curriculum(stages, "ppo")
