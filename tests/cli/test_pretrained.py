"""Policies shipped with the package: their cards hold, and every command takes them by name."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aftir_rl.cli import evaluate, pretrained, rollout
from aftir_rl.core.errors import ConfigError
from aftir_rl.experiments.runs import evaluate_run
from aftir_rl.rl.pretrained import card, load, names, policy_dir

NAMES = names()


def test_policies_ship_with_cards():
    assert "ppo-armreach" in NAMES
    for name in NAMES:
        c = card(name)
        assert c["name"] == name and c["env_id"].startswith("AFTIR-")
        assert c["test"]["targets"] >= 100 and 0.0 <= c["test"]["success_rate"] <= 1.0
        assert (policy_dir(name) / "model.zip").stat().st_size < 5_000_000  # a few MB at most


def test_unknown_name_is_one_catchable_error():
    with pytest.raises(ConfigError, match="ppo-armreach"):
        policy_dir("../../etc")


@pytest.mark.parametrize("name", NAMES)
def test_loaded_policy_acts_in_its_env(name):
    import gymnasium as gym

    model, env_id, kwargs = load(name)
    env = gym.make(env_id, **kwargs)
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action.astype(env.action_space.dtype))


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_card_numbers_are_measured_again(name):
    """The card's ``check`` set, measured now: the deterministic policy gives the same numbers
    on the kind of processor that measured them; on another, rounding in the network's matrix
    products may turn one episode of the set (seen: Intel Xeon against AMD EPYC)."""
    from aftir_rl.experiments.bench import machine_facts

    c = card(name)
    check = c["check"]
    row = evaluate_run(policy_dir(name), draw=(check["targets"], check["seed"]))
    same = c["machine"]["cpu"] == machine_facts()["cpu"]
    episode = 1e-9 if same else 1.0 / check["targets"] + 1e-9
    assert row["success_rate"] == pytest.approx(check["success_rate"], abs=episode)
    assert row["tip_error_cm"] == pytest.approx(check["tip_error_cm"], rel=1e-4 if same else 0.1)
    assert row["collision_rate"] == pytest.approx(check["collision_rate"], abs=episode)


def test_cli_lists_and_shows_cards(capsys):
    assert pretrained.main([]) == 0
    out = capsys.readouterr().out
    assert all(f"{name}:" in out for name in NAMES)
    assert pretrained.main(["ppo-armreach"]) == 0
    text = capsys.readouterr().out
    c = card("ppo-armreach")
    assert text.startswith("ppo-armreach: PPO on AFTIR-ArmReach-v0")
    assert f"{c['test']['success_rate']:.1%} success" in text
    assert " ".join(c["recipe"].split()) in " ".join(text.split())  # wrapped at 100 columns
    assert pretrained.main(["ppo-armreach", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == c
    assert pretrained.main(["no-such-policy"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no-such-policy" in err


def test_commands_take_a_pretrained_policy(tmp_path, capsys):
    logdir = tmp_path / "logs"
    assert (
        evaluate.main(["--pretrained", "ppo-armreach", "--random", "2", "--logdir", str(logdir)])
        == 0
    )
    assert "| ppo-armreach |" in capsys.readouterr().out
    out = tmp_path / "rollouts"
    args = ["--pretrained", "ppo-armreach", "--target", "20", "10", "60", "-o", str(out)]
    assert rollout.main(args) == 0
    (folder,) = out.iterdir()
    trajectory = json.loads((folder / "trajectory.json").read_text())
    assert np.allclose(trajectory["target"], [20, 10, 60])
    assert json.loads((folder / "summary.json").read_text())["run"] == "ppo-armreach"
    both = ["RUN", "--pretrained", "ppo-armreach", "--target", "1", "1", "1", "-o", str(out)]
    assert rollout.main(both) == 2
    assert evaluate.main(["--logdir", str(logdir)]) == 2
