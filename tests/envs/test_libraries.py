"""The envs from other RL libraries: TorchRL's ``GymEnv`` on every env id and on the vector env.

TorchRL wraps any Gymnasium env by id, checks its specs against a rollout
(``check_env_specs``) and runs a batch of them as a Gymnasium vector env in subprocesses
(``num_envs``). It passes ``frameskip`` to every env and drops it on Python's "unexpected keyword
argument" ``TypeError``, which the envs raise for an argument they do not take.
"""

from __future__ import annotations

import pytest

import aftir_rl

torchrl_envs = pytest.importorskip("torchrl.envs")
pytestmark = pytest.mark.slow


@pytest.mark.parametrize("env_id", aftir_rl.ENV_IDS)
def test_torchrl_wraps_every_env_and_its_specs_hold(env_id):
    from torchrl.envs.utils import check_env_specs

    env = torchrl_envs.GymEnv(f"aftir_rl:{env_id}")
    try:
        check_env_specs(env, seed=0)
        rollout = env.rollout(8)
        assert rollout.batch_size[0] >= 1 and ("next", "reward") in rollout.keys(True)
    finally:
        env.close()


def test_torchrl_runs_the_follow_the_leader_env_as_a_batch_in_subprocesses():
    from torchrl.envs.utils import check_env_specs

    env = torchrl_envs.GymEnv("aftir_rl:AFTIR-ArmFTL-v0", num_envs=2, bay=1)
    try:
        check_env_specs(env, seed=0)
        rollout = env.rollout(6)
        assert tuple(rollout.batch_size) == (2, 6)
    finally:
        env.close()
