from __future__ import annotations

import json
import pickle
from collections import deque

import gymnasium as gym
import numpy as np
import pytest
import yaml
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from aftir_rl import ENV_IDS
from aftir_rl.core.errors import CheckpointError, TargetError
from aftir_rl.envs import Action, TankGoalEnv, TankGridEnv
from aftir_rl.rl.tabular import GoalQLearning, QLearning, train_all_targets

START = (3, 2, 0)


def bfs(obstructed: np.ndarray, start: tuple[int, int, int]) -> dict:
    """Moves from ``start`` to every free cell it reaches (6-neighbourhood), written afresh."""
    dist = {start: 0}
    queue = deque([start])
    while queue:
        cur = queue.popleft()
        for axis in range(3):
            for step in (-1, 1):
                n = list(cur)
                n[axis] += step
                n = tuple(n)
                if 0 <= n[axis] < obstructed.shape[axis] and not obstructed[n] and n not in dist:
                    dist[n] = dist[cur] + 1
                    queue.append(n)
    return dist


@pytest.fixture(scope="module")
def goal_env():
    return gym.make("AFTIR-TankGoal-v0")


@pytest.fixture(scope="module")
def bfs_dist(goal_env):
    return bfs(np.asarray(goal_env.unwrapped.raster.obstructed), START)


@pytest.fixture(scope="module")
def trained():
    """One goal-conditioned run with the default hyperparameters (configs/q_table.yaml)."""
    return train_all_targets(seed=0)


# ------------------------------------------------------------------------------------- the env
def test_check_env(goal_env):
    gym_check_env(goal_env.unwrapped)
    sb3_check_env(goal_env.unwrapped, warn=True)


def test_spaces_and_registration(goal_env):
    assert "AFTIR-TankGoal-v0" in ENV_IDS
    assert goal_env.spec.max_episode_steps == 100
    space = goal_env.observation_space
    assert isinstance(space, gym.spaces.Dict)
    assert set(space.spaces) == {"observation", "achieved_goal", "desired_goal"}
    for sub in space.spaces.values():
        assert isinstance(sub, gym.spaces.MultiDiscrete) and sub.dtype == np.int64
        np.testing.assert_array_equal(sub.nvec, [15, 10, 5])
    assert goal_env.action_space == gym.spaces.Discrete(6)
    obs, info = goal_env.reset(seed=0)
    assert tuple(obs["observation"]) == START and tuple(obs["achieved_goal"]) == START
    assert tuple(obs["desired_goal"]) == info["target_cell"]
    assert isinstance(goal_env.unwrapped.grid, TankGridEnv)


def test_goals_drawn_from_reachable_cells_with_np_random(goal_env, bfs_dist):
    env = goal_env.unwrapped
    assert {tuple(c) for c in env.goal_cells} == {c for c, d in bfs_dist.items() if d > 0}
    assert len(env.goal_cells) == 586

    def goals(seed, n=300):
        out = [tuple(env.reset(seed=seed)[0]["desired_goal"])]
        out += [tuple(env.reset()[0]["desired_goal"]) for _ in range(n - 1)]
        return out

    a = goals(7)
    assert a == goals(7) and a != goals(8)
    assert START not in a and all(bfs_dist[g] > 0 for g in a)
    assert len(set(a)) > 200  # 300 uniform draws among 586 cells: about 234 distinct


def test_target_options_and_fixed_goal():
    env = gym.make("AFTIR-TankGoal-v0").unwrapped
    obs, info = env.reset(seed=0, options={"target": (-50, 72, 90)})
    assert tuple(obs["desired_goal"]) == (0, 6, 4) == info["target_cell"]
    np.testing.assert_array_equal(env.target_point, (-50, 72, 90))
    obs, _ = env.reset(options={"target_cell": (14, 9, 4)})
    assert tuple(obs["desired_goal"]) == (14, 9, 4)
    drawn = {tuple(env.reset()[0]["desired_goal"]) for _ in range(20)}
    assert len(drawn) > 1  # options hold for one episode only
    fixed = gym.make("AFTIR-TankGoal-v0", target=(230, 72, 10))
    assert {tuple(fixed.reset()[0]["desired_goal"]) for _ in range(5)} == {(14, 6, 0)}
    with pytest.raises(TargetError, match="obstructed"):
        env.reset(options={"target": (0, 60, 10)})
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"goal": (1, 1, 1)})


def test_step_rewards_and_hit_info():
    env = gym.make("AFTIR-TankGoal-v0").unwrapped
    env.reset(seed=0, options={"target_cell": (3, 2, 2)})
    obs, r, term, trunc, info = env.step(Action.Z_MINUS)  # the crust
    assert (r, term, trunc, info["hit"], info["is_success"]) == (-100.0, True, False, True, False)
    assert tuple(obs["achieved_goal"]) == START  # the tip stays
    env.reset(options={"target_cell": (3, 2, 2)})
    _, r1, t1, _, i1 = env.step(Action.Z_PLUS)
    obs, r2, t2, _, i2 = env.step(Action.Z_PLUS)
    assert (r1, t1, i1["hit"]) == (0.0, False, False)
    assert (r2, t2, i2["hit"], i2["is_success"]) == (100.0, True, False, True)
    assert tuple(obs["achieved_goal"]) == (3, 2, 2)


def _random_transitions(env, n_episodes, seed):
    """(state before, action, next achieved, desired, info, reward, terminated) of random play."""
    rng = np.random.default_rng(seed)
    out = []
    obs, _ = env.reset(seed=seed)
    for _ in range(n_episodes):
        for _ in range(100):
            a = int(rng.integers(6))
            prev = tuple(obs["achieved_goal"])
            obs, r, term, trunc, info = env.step(a)
            out.append((prev, a, obs["achieved_goal"], obs["desired_goal"], info, r, term))
            if term or trunc:
                break
        obs, _ = env.reset()
    return out


@pytest.mark.parametrize("step_penalty", [0.0, 1.0])
def test_compute_reward_matches_step_rewards_in_batches(step_penalty):
    env = gym.make("AFTIR-TankGoal-v0", step_penalty=step_penalty)
    base = env.unwrapped
    # Steer some episodes next to their goal so that +100 shows up among the random moves.
    data = _random_transitions(env, 300, seed=1)
    for goal in [(3, 2, 1), (4, 2, 0), (3, 3, 1)]:
        for a in range(6):
            env.reset(options={"target_cell": goal})
            o, r, t, _, i = env.step(a)
            data.append((START, a, o["achieved_goal"], o["desired_goal"], i, r, t))
    prev, actions, achieved, desired, infos, rewards, terminated = zip(*data)
    achieved, desired, rewards = np.array(achieved), np.array(desired), np.array(rewards)
    assert {-100.0, 100.0, -step_penalty} == set(rewards)
    for batch_infos in (list(infos), np.array(infos, dtype=object)):
        got = base.compute_reward(achieved, desired, batch_infos)
        assert got.shape == rewards.shape and got.dtype == np.float64
        np.testing.assert_array_equal(got, rewards)
        np.testing.assert_array_equal(
            base.compute_terminated(achieved, desired, batch_infos), np.array(terminated)
        )
        assert not base.compute_truncated(achieved, desired, batch_infos).any()
    # One info dict holding an array of hits works as well; a batch of shape (k, m, 3) too.
    hits = np.array([i["hit"] for i in infos])
    np.testing.assert_array_equal(base.compute_reward(achieved, desired, {"hit": hits}), rewards)
    k = len(rewards) // 2 * 2
    np.testing.assert_array_equal(
        base.compute_reward(
            achieved[:k].reshape(-1, 2, 3),
            desired[:k].reshape(-1, 2, 3),
            np.array(infos[:k], dtype=object).reshape(-1, 2),
        ),
        rewards[:k].reshape(-1, 2),
    )
    for i in range(0, len(data), 37):
        assert base.compute_reward(achieved[i], desired[i], infos[i]) == rewards[i]

    # Relabelled goals (what HER does) give the reward the plain grid world gives for that goal.
    rng = np.random.default_rng(2)
    grid = TankGridEnv(step_penalty=step_penalty)
    checked = 0
    for j in rng.choice(len(data), 300, replace=False):
        s, a, nxt = prev[j], actions[j], achieved[j]
        for goal in (tuple(nxt), tuple(base.goal_cells[rng.integers(len(base.goal_cells))])):
            if goal == s:  # the tip never sits on its goal during an episode
                continue
            grid.reset(options={"target_cell": goal})
            grid._state = grid.raster.index(s)
            _, r, term, _, _ = grid.step(a)
            assert base.compute_reward(nxt, np.array(goal), infos[j]) == r
            assert base.compute_terminated(nxt, np.array(goal), infos[j]) == term
            checked += 1
    assert checked > 400


def test_compute_reward_without_infos():
    base = TankGoalEnv()
    a = np.array([[3, 2, 0], [3, 2, 1]])
    d = np.array([[3, 2, 1], [3, 2, 1]])
    np.testing.assert_array_equal(base.compute_reward(a, d, None), [0.0, 100.0])
    np.testing.assert_array_equal(base.compute_reward(a, d, [{}, {}]), [0.0, 100.0])
    np.testing.assert_array_equal(base.compute_reward(a, d, [{"hit": True}, {}]), [-100.0, 100.0])
    with pytest.raises(ValueError, match="last axis of 3"):
        base.compute_reward(np.zeros(2), np.zeros(2), None)


def test_dynamics_agree_with_the_grid_model(goal_env):
    nxt, hit = goal_env.unwrapped.dynamics()
    assert nxt.shape == hit.shape == (750, 6) and not nxt.flags.writeable
    raster = goal_env.unwrapped.raster
    free = [raster.index(c) for c in goal_env.unwrapped.goal_cells]
    rng = np.random.default_rng(3)
    for target in [(0, 6, 4), (14, 9, 4), *[raster.cell(s) for s in rng.choice(free, 5)]]:
        grid = TankGridEnv(target_cell=target)
        rows = [s for s in free + [grid.start_state] if s != grid.target_state]
        np.testing.assert_array_equal(nxt[rows], grid.next_state[rows])
        np.testing.assert_array_equal(hit[rows], grid.reward_table[rows] == -100.0)
    # The goal env's own model still points at its current goal.
    assert goal_env.unwrapped.target_state == goal_env.unwrapped.raster.index(
        goal_env.unwrapped.target_cell
    )


def test_seeded_rollouts_are_identical():
    def rollout(seed):
        env = gym.make("AFTIR-TankGoal-v0")
        env.action_space.seed(seed)
        obs, _ = env.reset(seed=seed)
        out = [gym.spaces.flatten(env.observation_space, obs)]
        for _ in range(300):
            obs, r, term, trunc, _ = env.step(env.action_space.sample())
            out.append(np.r_[gym.spaces.flatten(env.observation_space, obs), r, term, trunc])
            if term or trunc:
                out.append(gym.spaces.flatten(env.observation_space, env.reset()[0]))
        return out

    a, b = rollout(3), rollout(3)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    c = rollout(4)
    assert len(a) != len(c) or any(not np.array_equal(x, y) for x, y in zip(a, c))


def test_render_and_pickle():
    env = gym.make("AFTIR-TankGoal-v0", render_mode="ansi")
    env.reset(seed=0, options={"target_cell": (14, 9, 4)})
    env.step(Action.Z_PLUS)
    text = env.render()
    assert "S" in text and "A" in text and "T" in text
    clone = pickle.loads(pickle.dumps(env))
    a, b = clone.step(Action.Z_PLUS), env.step(Action.Z_PLUS)
    for key in a[0]:
        np.testing.assert_array_equal(a[0][key], b[0][key])
    assert a[1:4] == b[1:4]


# --------------------------------------------------------------- goal-conditioned Q-learning
def test_one_run_learns_a_bfs_shortest_path_to_every_reachable_cell(trained, bfs_dist):
    agent, summary = trained
    assert agent.q_table.shape == (750, 586, 6)
    targets = [c for c, d in bfs_dist.items() if d > 0]
    assert len(targets) == 586 == summary["n_goals"]
    obstructed = np.asarray(agent.raster.obstructed)
    for goal in targets:
        cells, ok = agent.greedy_path(goal)
        assert ok and cells[0] == START and cells[-1] == goal
        for a, b in zip(cells, cells[1:]):
            assert np.abs(np.subtract(a, b)).sum() == 1 and not obstructed[b]
        assert len(cells) - 1 == bfs_dist[goal], goal
    assert summary["all_optimal"] and summary["n_optimal"] == summary["n_reached"] == 586
    lengths = agent.greedy_path_lengths()
    assert lengths.tolist() == [bfs_dist[tuple(c)] for c in agent.goal_cells]


def test_greedy_policy_drives_the_goal_env(trained, bfs_dist):
    agent, _ = trained
    env = gym.make("AFTIR-TankGoal-v0")
    env.reset(seed=5)
    for _ in range(25):
        obs, info = env.reset()
        steps, term, trunc = 0, False, False
        while not (term or trunc):
            obs, r, term, trunc, info = env.step(agent.predict(obs)[0])
            steps += 1
        assert info["is_success"] and r == 100.0
        assert steps == bfs_dist[tuple(obs["desired_goal"])]


def test_same_seed_same_table():
    env = TankGoalEnv()

    def run(seed):
        return GoalQLearning(env, seed=seed).learn(60).q_table

    np.testing.assert_array_equal(run(4), run(4))
    assert not np.array_equal(run(4), run(5))


def test_save_load_resume(tmp_path):
    env = gym.make("AFTIR-TankGoal-v0")
    agent = GoalQLearning(env, seed=1).learn(40)
    path = agent.save(tmp_path / "goal_q", extra={"note": "test"})
    assert path.name == "goal_q.npz" and [p.name for p in tmp_path.iterdir()] == ["goal_q.npz"]
    loaded = GoalQLearning.load(path, env)
    np.testing.assert_array_equal(loaded.q_table, agent.q_table)
    assert loaded.hyperparameters() == agent.hyperparameters()
    assert (loaded.episodes_done, loaded.num_timesteps) == (40, agent.num_timesteps)
    assert GoalQLearning.read_checkpoint(path)[2]["note"] == "test"
    # The loaded agent continues exactly as the one in memory (table, ε schedule, generator).
    loaded.learn(30)
    agent.learn(30)
    np.testing.assert_array_equal(loaded.q_table, agent.q_table)
    assert loaded.episodes_done == 70


def test_bad_checkpoints(tmp_path):
    env = TankGoalEnv()
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(CheckpointError, match="not a readable goal Q-table"):
        GoalQLearning.load(bad, env)
    with pytest.raises(CheckpointError, match="no such goal Q-table"):
        GoalQLearning.load(tmp_path / "missing.npz", env)
    plain = QLearning(gym.make("AFTIR-Tank-v0")).save(tmp_path / "plain.npz")
    with pytest.raises(CheckpointError, match="not a readable|not an aftir_rl goal"):
        GoalQLearning.load(plain, env)
    # A tank with one more obstacle has other goal cells: the table does not fit it.
    data = yaml.safe_load(open(env.tank.source))
    data["obstacles"].append(
        {"name": "plug", "type": "box", "min": [161, 111, 1], "max": [179, 129, 19]}
    )
    other = tmp_path / "plugged.yaml"
    other.write_text(yaml.safe_dump(data))
    path = GoalQLearning(env).save(tmp_path / "q.npz")
    with pytest.raises(CheckpointError, match="tank it was trained on"):
        GoalQLearning.load(path, TankGoalEnv(tank=str(other)))
    # Metadata from a file is checked key by key before it reaches the constructor.
    with np.load(path) as data:
        arrays = {k: data[k] for k in ("q_table", "goal_cells")}
        meta = json.loads(str(data["metadata"]))
    for change, message in (
        ({"evil": 1}, "hyperparameters must hold exactly"),
        ({"max_episode_steps": 10**12}, "max_episode_steps"),
        ({"gamma": 7}, "gamma"),
    ):
        hostile = {**meta, "hyperparameters": {**meta["hyperparameters"], **change}}
        tampered = tmp_path / "tampered.npz"
        np.savez(tampered, **arrays, metadata=np.array(json.dumps(hostile)))
        with pytest.raises(CheckpointError, match=message):
            GoalQLearning.load(tampered, env)
    np.savez(tampered, **arrays, metadata=np.array(json.dumps({**meta, "rng_state": [1, 2]})))
    with pytest.raises(CheckpointError, match="rng_state"):
        GoalQLearning.load(tampered, env)


def test_needs_the_goal_env():
    with pytest.raises(TypeError, match="AFTIR-TankGoal-v0"):
        GoalQLearning(gym.make("AFTIR-Tank-v0"))
    agent = GoalQLearning(TankGoalEnv())
    with pytest.raises(TargetError, match="not a goal"):
        agent.greedy_path(START)
    with pytest.raises(TargetError, match="not a goal"):
        agent.greedy_path((3, 1, 0))  # obstructed


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_other_seeds_reach_every_cell_optimally(seed, bfs_dist):
    agent, summary = train_all_targets(seed=seed)
    assert summary["all_optimal"], summary["not_optimal"]
    assert agent.greedy_path_lengths().tolist() == [bfs_dist[tuple(c)] for c in agent.goal_cells]


# ------------------------------------------------------------------------------- SB3 + HER
def test_sb3_dqn_with_her_trains():
    import torch
    from stable_baselines3 import DQN, HerReplayBuffer

    torch.set_num_threads(1)
    env = gym.make("AFTIR-TankGoal-v0", max_episode_steps=30)
    model = DQN(
        "MultiInputPolicy",
        env,
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={
            "n_sampled_goal": 4,
            "goal_selection_strategy": "future",
            "copy_info_dict": True,
        },
        learning_starts=64,
        batch_size=32,
        buffer_size=2_000,
        policy_kwargs={"net_arch": [32]},
        seed=0,
        device="cpu",
    )
    model.learn(300)
    assert model.num_timesteps == 300
    batch = model.replay_buffer.sample(256, env=model.get_vec_normalize_env())
    assert set(batch.rewards.flatten().tolist()) <= {-100.0, 0.0, 100.0}
    assert 100.0 in batch.rewards  # relabelled goals are reached
    action, _ = model.predict(env.reset(seed=0)[0], deterministic=True)
    assert 0 <= int(action) < 6
