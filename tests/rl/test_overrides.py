"""``--env-kwargs`` and ``--hyperparams``: read as YAML, checked like a config file."""

from __future__ import annotations

import pytest

from aftir_rl.core.errors import ConfigError
from aftir_rl.rl.sb3 import load_sb3_config
from aftir_rl.rl.sb3.hyperparams import MAX_ITEMS, parse_key_values, with_overrides


def test_values_are_yaml_not_python():
    got = parse_key_values(
        ["bay:1", "guide:true", "shaping:field", "net:[64, 64]", "kw:{net_arch: [8]}", "x:"],
        "--env-kwargs",
    )
    assert got == {
        "bay": 1,
        "guide": True,
        "shaping": "field",
        "net": [64, 64],
        "kw": {"net_arch": [8]},
        "x": None,
    }
    assert parse_key_values(["f:__import__('os').system('true')"], "--x") == {
        "f": "__import__('os').system('true')"  # a string, never evaluated
    }


@pytest.mark.parametrize(
    "items, match",
    [
        (["bay"], "KEY:VALUE"),
        (["1bay:2"], "KEY:VALUE"),
        (["bay:1", "bay:2"], "twice"),
        (["bay:[1"], "not valid YAML"),
        (["bay:1\nguide: true"], "one line"),
        (["a:!!python/object:os.system {}"], "YAML"),
        ([f"k{i}:1" for i in range(MAX_ITEMS + 1)], "at most"),
        (["a:&x [*x]"], "YAML"),
    ],
)
def test_bad_items_are_one_line_errors(items, match):
    with pytest.raises(ConfigError, match=match) as info:
        parse_key_values(items, "--env-kwargs")
    assert "\n" not in str(info.value)


def test_overrides_merge_into_the_config_and_are_checked():
    config = load_sb3_config("ppo_ftl", "ppo")
    merged = with_overrides(
        config, "ppo", ["bay:1"], ["learning_rate:1e-4", "policy_kwargs:{net_arch: [32, 32]}"]
    )
    assert merged.env_kwargs == {**config.env_kwargs, "bay": 1}
    assert merged.hyperparameters["learning_rate"] == pytest.approx(1e-4)
    assert merged.hyperparameters["policy_kwargs"] == {"net_arch": [32, 32]}
    assert merged.hyperparameters["n_steps"] == config.hyperparameters["n_steps"]
    assert with_overrides(config, "ppo") is config
    for env, hyper, match in (
        (["bay:[1]"], [], "bay"),
        (["nope:1"], [], "unknown key 'nope'"),
        ([], ["n_epochs:0"], "n_epochs"),
        ([], ["buffer_size:10"], "unknown key 'buffer_size' for PPO"),
        ([], ["policy_kwargs:{activation_fn: ReLU}"], "policy_kwargs"),
    ):
        with pytest.raises(ConfigError, match=match):
            with_overrides(config, "ppo", env, hyper)
