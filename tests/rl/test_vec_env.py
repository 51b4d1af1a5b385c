"""``make_sb3_vec_env``: the SB3 VecEnv of any env of the package, for other code."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

from aftir_rl.core.errors import ConfigError
from aftir_rl.rl.sb3 import make_sb3_vec_env
from aftir_rl.rl.sb3.vec_adapter import SB3VectorEnv


@pytest.mark.parametrize(
    "env_id, kwargs, policy, batched",
    [
        ("AFTIR-ArmFTL-v0", {"bay": 2, "guide": True}, "MultiInputPolicy", True),
        ("AFTIR-ArmReach-v0", {}, "MlpPolicy", False),
    ],
)
def test_sb3_trains_on_it(env_id, kwargs, policy, batched):
    venv = make_sb3_vec_env(env_id, n_envs=4, seed=0, **kwargs)
    assert venv.num_envs == 4
    if batched:
        assert isinstance(venv, VecMonitor) and isinstance(venv.venv, SB3VectorEnv)
    else:
        assert isinstance(venv, DummyVecEnv)
    model = PPO(policy, venv, n_steps=16, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(64)
    assert model.num_timesteps == 64
    obs = venv.reset()
    action, _ = model.predict(obs, deterministic=True)
    assert np.asarray(action).shape[0] == 4
    venv.close()


@pytest.mark.parametrize(
    "env_id, n_envs", [("CartPole-v1", 2), ("os:system", 2), ("AFTIR-ArmReach-v0", 0)]
)
def test_bad_arguments_are_one_line(env_id, n_envs):
    with pytest.raises(ConfigError) as err:
        make_sb3_vec_env(env_id, n_envs=n_envs)
    assert "\n" not in str(err.value)
