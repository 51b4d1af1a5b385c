"""The envs in the RL libraries people train with: their checks, and short runs that learn.

- Gymnasium: ``check_env`` on every id (``test_envs.py``); here ``gym.make_vec`` on every id
  (each row resets on the step after it ends, ``NextStep``, the same for the same seed), and the
  batched follow-the-leader env's ``SameStep`` ends in the form Gymnasium's own ``SyncVectorEnv``
  gives (what TorchRL reads).
- RLlib's env runner, configured as ``aftir train --rllib`` configures it, samples every id
  with PPO's default module.
- TorchRL wraps any Gymnasium env by id, checks its specs against a rollout
  (``check_env_specs``) and runs a batch of them as a Gymnasium vector env in subprocesses
  (``num_envs``), or wraps the batched env itself (``GymWrapper``). It passes ``frameskip`` to
  every env and drops it on Python's "unexpected keyword argument" ``TypeError``, which the envs
  raise for an argument they do not take.
- Learning: ``examples/cleanrl_ppo.py`` (CleanRL's single-file PPO on ``gym.make_vec`` alone)
  and ``examples/torchrl_ppo.py`` (TorchRL's collector and PPO loss) train the batched env on
  bay-1 targets for 1M and 0.6M steps (under a minute each) and must beat uniformly random
  actions on 32 fixed targets by at least 4 successes (random reaches none there); RLlib's run is in
  ``tests/rl/test_rllib.py``, SB3's in ``tests/cli``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import aftir_rl

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[2]
#: Bay-1 targets, the guide in the observation, progress shaping: learnable in a minute.
BAY1 = json.dumps({"bay": 1, "guide": True, "shaping": True})
#: Successes (of 32) a short run must have beyond random actions'.
MARGIN = 4


@pytest.mark.parametrize("env_id", aftir_rl.ENV_IDS)
def test_every_env_makes_a_vector_env_that_resets_rows_on_the_next_step(env_id):
    def run(seed: int) -> list[np.ndarray]:
        envs = gym.make_vec(f"aftir_rl:{env_id}", num_envs=2)
        assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
        envs.action_space.seed(seed)
        obs, _ = envs.reset(seed=seed)
        out, ended, previous = [], 0, np.zeros(2, dtype=bool)
        for _ in range(400):
            obs, reward, terminated, truncated, _ = envs.step(envs.action_space.sample())
            # a row that ended is reset by this step: reward 0, not ended again
            assert np.all(reward[previous] == 0) and not np.any((terminated | truncated)[previous])
            previous = terminated | truncated
            ended += int(previous.sum())
            flat = gym.spaces.flatten(envs.observation_space, obs).astype(float)
            out.append(np.concatenate([flat, reward, terminated, truncated]))
            if ended >= 2:
                break
        envs.close()
        assert ended >= 1, "no row ended in 400 random steps"
        return out

    first, again = run(3), run(3)
    assert len(first) == len(again)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)


def test_same_step_ends_look_like_gymnasiums_own_vector_env():
    kwargs = {"bay": 1, "max_episode_steps": 5}
    ours = gym.make_vec("aftir_rl:AFTIR-ArmFTL-v0", num_envs=2, autoreset_mode="SameStep", **kwargs)
    theirs = gym.vector.SyncVectorEnv(
        [lambda: gym.make("AFTIR-ArmFTL-v0", **kwargs)] * 2, autoreset_mode="SameStep"
    )
    ours.reset(seed=1)
    theirs.reset(seed=1)
    actions = np.random.default_rng(0).uniform(-1, 1, (5, 2, 3)).astype(np.float32)
    for a in actions:
        step_ours, step_theirs = ours.step(a), theirs.step(a)
    info, ref = step_ours[-1], step_theirs[-1]
    assert info["_final_obs"].tolist() == ref["_final_obs"].tolist() == [True, True]
    assert info["final_obs"].dtype == ref["final_obs"].dtype == object
    for mine, other in zip(info["final_obs"], ref["final_obs"]):
        assert mine.keys() == other.keys()
        for key in mine:
            np.testing.assert_array_equal(mine[key], other[key])
    for key in ("is_success", "contact", "distance_cm"):
        np.testing.assert_array_equal(info["final_info"][key], ref["final_info"][key])
        assert info["final_info"][f"_{key}"].tolist() == ref["final_info"][f"_{key}"].tolist()


@pytest.mark.parametrize("env_id", aftir_rl.ENV_IDS)
def test_torchrl_wraps_every_env_and_its_specs_hold(env_id):
    torchrl_envs = pytest.importorskip("torchrl.envs")
    from torchrl.envs.utils import check_env_specs

    env = torchrl_envs.GymEnv(f"aftir_rl:{env_id}")
    try:
        check_env_specs(env, seed=0)
        rollout = env.rollout(8)
        assert rollout.batch_size[0] >= 1 and ("next", "reward") in rollout.keys(True)
    finally:
        env.close()


def test_the_env_pages_torchrl_snippet_runs_and_its_batches_hold(monkeypatch):
    """The snippet of docs/envs/index.md as printed: subprocess copies, then the batched env."""
    pytest.importorskip("torchrl")
    import re

    text = (ROOT / "docs" / "envs" / "index.md").read_text()
    (code,) = re.findall(r"```python\n(.*?)```", text, re.S)
    monkeypatch.syspath_prepend(str(ROOT))
    names: dict = {}
    exec(compile(code, "docs/envs/index.md", "exec"), names)
    try:
        assert tuple(names["batch"].batch_size) == (2, 6)
        steps = names["steps"]
        assert tuple(steps.batch_size) == (64, 300)
        done = steps["next", "done"].squeeze(-1)
        assert done.any(), "no row ended in 300 steps"
        # a row that ended starts again with a new target; one that did not keeps its own
        space = names["venv"].single_observation_space
        start = 0
        for key, sub in space.items():
            if key == "desired_goal":
                break
            start += int(np.prod(sub.shape))
        goal = slice(start, start + 3)
        last = steps["next", "observation"][:, :-1, goal].numpy()
        first = steps["observation"][:, 1:, goal].numpy()
        ended = done[:, :-1].numpy()
        assert ended.any()
        np.testing.assert_array_equal(last[~ended], first[~ended])
        assert np.all(np.abs(last[ended] - first[ended]).max(axis=-1) > 0)
    finally:
        names["env"].close()
        names["batched"].close()


@pytest.mark.parametrize("env_id", aftir_rl.ENV_IDS)
def test_rllib_samples_every_env_with_ppos_module(env_id):
    """RLlib's env runner as ``aftir train --rllib`` configures it, without Ray: one-hot for the
    grid worlds' ``Discrete`` observations, flattened ``Dict`` s, the batched env as one."""
    pytest.importorskip("ray.rllib")
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

    from aftir_rl.rl.rllib.config import flatten_connector
    from aftir_rl.rl.sb3.config import BATCHED_ENV_IDS

    mode = "vector_entry_point" if env_id in BATCHED_ENV_IDS else "sync"
    config = (
        PPOConfig()
        .environment(f"aftir_rl:{env_id}")
        .env_runners(
            num_env_runners=0,
            num_envs_per_env_runner=2,
            env_to_module_connector=flatten_connector,
            gym_env_vectorize_mode=mode,
        )
    )
    runner = SingleAgentEnvRunner(config=config)
    try:
        episodes = runner.sample(num_timesteps=64, random_actions=False)
        assert sum(len(e) for e in episodes) >= 64
        for episode in episodes:
            assert np.all(np.isfinite(episode.get_rewards()))
    finally:
        runner.stop()


def _example(script: str, *args: str) -> dict:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    out = subprocess.run(
        [sys.executable, str(ROOT / "examples" / script), *args, "--json"],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_cleanrl_style_ppo_on_make_vec_alone_learns_to_reach_targets():
    result = _example(
        "cleanrl_ppo.py", "--env-kwargs", BAY1, "--total-timesteps", "1000000", "--num-envs", "64"
    )
    assert result["steps"] >= 990_000 and result["eval_episodes"] == 32
    wins, random_wins = (round(32 * result[k]) for k in ("success", "random_success"))
    assert wins >= random_wins + MARGIN, result


def test_torchrl_ppo_on_the_batched_env_learns_to_reach_targets():
    pytest.importorskip("torchrl")
    result = _example("torchrl_ppo.py", "--env-kwargs", BAY1, "--total-frames", "602112")
    assert result["steps"] == 602112 and result["eval_episodes"] == 32
    wins, random_wins = (round(32 * result[k]) for k in ("success", "random_success"))
    assert wins >= random_wins + MARGIN, result


@pytest.mark.parametrize("script", ["cleanrl_ppo.py", "torchrl_ppo.py"])
@pytest.mark.parametrize(
    "args", [["--env-kwargs", "{not json"], ["--env-kwargs", '{"bay": 7}'], ["--num-envs", "0"]]
)
def test_the_examples_refuse_bad_arguments_in_one_line(script, args, tmp_path, capsys, monkeypatch):
    if script == "torchrl_ppo.py":
        pytest.importorskip("torchrl")
    import importlib.util

    spec = importlib.util.spec_from_file_location(script[:-3], ROOT / "examples" / script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_:
        module.main(args)
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and "Traceback" not in err[-1] and "error:" in err[-1]
    assert not list(tmp_path.iterdir())
