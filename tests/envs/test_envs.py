from __future__ import annotations

import pickle
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
import yaml
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from aftir_rl import ENV_IDS
from aftir_rl.core.errors import InvalidActionError, TargetError
from aftir_rl.envs import Action, TankGridEnv


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env(env_id):
    env = gym.make(env_id)
    gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=True)


#: Random steps per rollout; the route env's episodes mostly end at a random first action
#: (not a lead), and each reset weighs every lead with the planner's moves: fewer steps.
ROLLOUT_STEPS = {"AFTIR-ArmRoute-v1": 30, "AFTIR-ArmRoute-v0": 30}


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_seeded_rollouts_are_identical(env_id):
    def rollout(seed):
        env = gym.make(env_id)

        def flat(o):
            return gym.spaces.flatten(env.observation_space, o).astype(float)

        env.action_space.seed(seed)
        obs, _ = env.reset(seed=seed)
        out = [flat(obs)]
        for _ in range(ROLLOUT_STEPS.get(env_id, 150)):
            obs, r, term, trunc, _ = env.step(env.action_space.sample())
            out.append(np.concatenate([flat(obs), [r, term, trunc]]))
            if term or trunc:
                out.append(flat(env.reset()[0]))
        return out

    a, b = rollout(3), rollout(3)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_pickle_round_trip(env_id):
    env = gym.make(env_id)
    env.reset(seed=0)
    env.action_space.seed(0)
    action = env.action_space.sample()
    env.step(action)
    clone = pickle.loads(pickle.dumps(env))
    a, b = clone.step(action), env.step(action)
    flat = gym.spaces.flatten
    np.testing.assert_array_equal(
        flat(env.observation_space, a[0]), flat(env.observation_space, b[0])
    )
    assert a[1:4] == b[1:4]


def test_make_from_fresh_interpreter():
    code = (
        "import gymnasium as gym; e = gym.make('aftir_rl:AFTIR-Tank-v0'); print(e.reset(seed=0)[0])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == str(np.ravel_multi_index((3, 2, 0), (15, 10, 5)))


def test_spaces_and_registration():
    env = gym.make("AFTIR-Tank-v0")
    assert env.observation_space == gym.spaces.Discrete(750)
    assert env.action_space == gym.spaces.Discrete(6)
    assert env.spec.max_episode_steps == 500
    assert [a.name for a in Action] == [
        "X_PLUS",
        "X_MINUS",
        "Y_PLUS",
        "Y_MINUS",
        "Z_PLUS",
        "Z_MINUS",
    ]


def _walk(env, actions):
    out = []
    for a in actions:
        out.append(env.step(a))
    return out


def test_rewards_and_termination():
    env = gym.make("AFTIR-Tank-v0", target_cell=(3, 2, 2)).unwrapped
    s, info = env.reset(seed=0)
    assert env.raster.cell(s) == (3, 2, 0)
    # Down from the floor: the crust. -100, terminated, the tip stays.
    nxt, r, term, trunc, _ = env.step(Action.Z_MINUS)
    assert (nxt, r, term, trunc) == (s, -100.0, True, False)
    env.reset()
    (s1, r1, t1, _, _), (s2, r2, t2, _, i2) = _walk(env, [Action.Z_PLUS, Action.Z_PLUS])
    assert env.raster.cell(s1) == (3, 2, 1) and (r1, t1) == (0.0, False)
    assert env.raster.cell(s2) == (3, 2, 2) and (r2, t2) == (100.0, True) and i2["is_success"]
    # Into the stringer row (b = 1, c = 0): obstructed.
    env.reset()
    nxt, r, term, _, _ = env.step(Action.Y_MINUS)
    assert env.raster.cell(nxt) == (3, 2, 0) and r == -100.0 and term


def test_step_penalty_and_truncation():
    env = gym.make("AFTIR-Tank-v0", step_penalty=1.0, max_episode_steps=3)
    env.reset(seed=0)
    results = _walk(env, [Action.X_PLUS, Action.X_MINUS, Action.X_PLUS])
    assert [r[1] for r in results] == [-1.0, -1.0, -1.0]
    assert results[-1][3] is True and results[-1][2] is False


def test_model_P_matches_step():
    env = gym.make("AFTIR-Tank-v0").unwrapped
    rng = np.random.default_rng(0)
    free = np.flatnonzero(~env.raster.obstructed.ravel())
    for s in rng.choice(free, 40, replace=False):
        for a in range(6):
            env.reset()
            env._state = int(s)
            nxt, r, term, _, _ = env.step(a)
            assert env.P[int(s)][a] == [(1.0, nxt, r, term)]


def test_target_by_keyword_and_options(tank):
    env = gym.make("AFTIR-Tank-v0", target=(-50, 72, 90)).unwrapped
    assert env.target_cell == (0, 6, 4)
    env.reset(options={"target_cell": (14, 9, 4)})
    assert env.target_cell == (14, 9, 4)
    env.reset(options={"target": (230, 72, 10)})
    assert env.target_cell == (14, 6, 0)
    assert env.P[env.target_state][0] == [(1.0, env.target_state, 0.0, True)]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"target": (500, 0, 10)}, "outside the tank box"),
        ({"target": (0, 60, 10)}, "obstructed cell"),
        ({"target_cell": (15, 0, 0)}, "outside the raster"),
        ({"target": (0, 0, 50), "target_cell": (1, 1, 1)}, "not both"),
    ],
)
def test_bad_targets(kwargs, message):
    with pytest.raises(TargetError, match=message):
        gym.make("AFTIR-Tank-v0", **kwargs)


def test_unreachable_target(tmp_path, tank):
    # Block the three neighbours of corner cell (0, 9, 0) with boxes inside them: the corner stays
    # free but cannot be reached.
    data = yaml.safe_load(open(tank.source))
    data["obstacles"] += [
        {"name": "plug_x", "type": "box", "min": [-39, 131, 1], "max": [-21, 149, 19]},
        {"name": "plug_y", "type": "box", "min": [-59, 111, 1], "max": [-41, 129, 19]},
        {"name": "plug_z", "type": "box", "min": [-59, 131, 21], "max": [-41, 149, 39]},
    ]
    path = tmp_path / "walled.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(TargetError, match="cannot be reached"):
        gym.make("AFTIR-Tank-v0", tank=str(path), target=(-50, 140, 10))


def test_invalid_actions_raise():
    env = gym.make("AFTIR-Tank-v0")
    env.reset(seed=0)
    for bad in (6, -1, 1.5, "up", None):
        with pytest.raises(InvalidActionError, match="invalid action"):
            env.step(bad)
    env.step(np.int64(4))  # numpy integers are fine


def test_render_modes():
    env = gym.make("AFTIR-Tank-v0", render_mode="ansi")
    env.reset(seed=0)
    env.step(Action.Z_PLUS)
    text = env.render()
    assert "S" in text and "A" in text and "T" in text
    env = gym.make("AFTIR-Tank-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(Action.Z_PLUS)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.std() > 10  # a picture, not a blank canvas
    with pytest.raises(ValueError, match="render_mode"):
        TankGridEnv(render_mode="video")
