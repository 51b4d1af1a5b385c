"""``AFTIR-ArmFTL-v0`` with a pool of generated tanks: a tank per episode, one goal space."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import aftir_rl  # noqa: F401  (registers the envs)
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.tank import load_tank
from aftir_rl.envs.ftl.pool import MAX_POOL, pool_specs


def test_each_episode_draws_a_tank_of_the_pool():
    env = gym.make("AFTIR-ArmFTL-v0", tank="wing:2:0-3", bay=2)
    seen = {}
    for episode in range(10):
        obs, info = env.reset(seed=episode)
        assert env.observation_space.contains(obs)
        tank = load_tank(info["tank"])
        lo, hi = tank.bay(2)
        assert np.all((info["target"] > lo) & (info["target"] < hi))  # this tank's bay 2
        assert tank.distance(info["target"]) >= 5.0
        obs, *_ = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        seen.setdefault(info["tank"], episode)
    assert len(seen) >= 3
    again = gym.make("AFTIR-ArmFTL-v0", tank="wing:2:0-3", bay=2)
    for episode in (0, 5):  # a seed gives the same tank and target
        _, first = env.reset(seed=episode)
        _, second = again.reset(seed=episode)
        assert first["tank"] == second["tank"]
        np.testing.assert_array_equal(first["target"], second["target"])


def test_sync_vector_envs_draw_their_own_tanks():
    envs = gym.make_vec("AFTIR-ArmFTL-v0", 2, vectorization_mode="sync", tank="wing:2:0-7", bay=1)
    _, info = envs.reset(seed=[3, 4])
    assert len(info["tank"]) == 2
    envs.step(envs.action_space.sample())


def test_pools_are_refused_where_one_tank_is_needed():
    with pytest.raises(ConfigError, match="runs in the single env"):
        gym.make_vec("AFTIR-ArmFTL-v0", 4, tank="wing:2:0-3")
    with pytest.raises(ConfigError, match="is a pool of generated tanks"):
        load_tank("wing:2:0-3")
    with pytest.raises(ConfigError, match=f"1 to {MAX_POOL} seeds"):
        pool_specs("wing:2:5-1")
    with pytest.raises(ConfigError, match=f"1 to {MAX_POOL} seeds"):
        pool_specs(f"wing:2:0-{MAX_POOL}")
    assert pool_specs("wing:2:7") is None and pool_specs("b737_center") is None
