from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from aftir_rl.core.errors import CheckpointError
from aftir_rl.rl.tabular import QLearning, QLearningConfig, greedy_rollout

CFG = QLearningConfig()


def _agent(env, seed=0):
    return QLearning.from_config(env, CFG, seed=seed)


def _random_free_points(grid, dist, n, seed):
    rng = np.random.default_rng(seed)
    cells = sorted(c for c in dist if dist[c] > 0)
    picks = [cells[i] for i in rng.choice(len(cells), n, replace=False)]
    # A point inside the cell, not its centre.
    origin = np.array([-60.0, -50.0, 0.0])
    return [tuple(origin + 20 * np.array(c) + rng.uniform(1, 19, 3)) for c in picks]


def _check_optimal(target, dist, seed=0):
    env = gym.make("AFTIR-Tank-v0", target=target, max_episode_steps=CFG.max_episode_steps)
    agent = _agent(env, seed).learn(CFG.episodes)
    states, success = greedy_rollout(agent, env)
    cells = [env.unwrapped.raster.cell(s) for s in states]
    assert success and cells[-1] == env.unwrapped.target_cell
    assert cells[0] == (3, 2, 0)
    for a, b in zip(cells, cells[1:]):
        assert np.abs(np.subtract(a, b)).sum() == 1  # one cell per step
    assert len(cells) - 1 == dist[env.unwrapped.target_cell], "greedy path is a BFS shortest path"


@pytest.mark.parametrize("target", [(230, 140, 90), (-50, 140, 10), (-50, 72, 90), (230, 72, 10)])
def test_reference_targets_reach_bfs_optimum(target, scene_grid):
    _check_optimal(target, scene_grid[1])


def test_random_free_targets_reach_bfs_optimum(scene_grid):
    grid, dist = scene_grid
    for target in _random_free_points(grid, dist, 6, seed=11):
        _check_optimal(target, dist)


def test_many_random_targets_and_seeds(scene_grid):
    grid, dist = scene_grid
    for seed, target in enumerate(_random_free_points(grid, dist, 40, seed=12)):
        _check_optimal(target, dist, seed=seed)


def test_frozen_lake_optimal():
    env = gym.make("FrozenLake-v1", map_name="4x4", is_slippery=False)
    agent = QLearning(env, gamma=0.95, exploration_decay=0.99, initial_q=1.0, seed=0).learn(500)
    states, success = greedy_rollout(agent, env)
    assert success and len(states) - 1 == 6  # Manhattan distance from (0, 0) to (3, 3)


def test_same_seed_same_table():
    def run(seed):
        env = gym.make("AFTIR-Tank-v0", target=(-50, 72, 90))
        return _agent(env, seed).learn(300).q_table

    np.testing.assert_array_equal(run(4), run(4))
    assert not np.array_equal(run(4), run(5))


def test_save_load_resume(tmp_path):
    env = gym.make("AFTIR-Tank-v0", target=(230, 72, 10))
    agent = _agent(env).learn(200)
    path = agent.save(tmp_path / "q", extra={"target": [230, 72, 10]})
    assert path.name == "q.npz" and [p.name for p in tmp_path.iterdir()] == ["q.npz"]
    loaded = QLearning.load(path, env)
    np.testing.assert_array_equal(loaded.q_table, agent.q_table)
    assert loaded.episodes_done == 200 and loaded.hyperparameters() == agent.hyperparameters()
    assert QLearning.read_checkpoint(path)[1]["target"] == [230, 72, 10]
    # Resuming continues the same generator: 200 + 100 equals 300 in one go.
    loaded.learn(100)
    straight = _agent(env).learn(300)
    np.testing.assert_array_equal(loaded.q_table, straight.q_table)
    assert loaded.episodes_done == 300


def test_corrupt_and_mismatched_checkpoints(tmp_path):
    env = gym.make("AFTIR-Tank-v0")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"this is not a zip file")
    with pytest.raises(CheckpointError, match="not a readable Q-table"):
        QLearning.load(bad, env)
    with pytest.raises(CheckpointError, match="no such Q-table file"):
        QLearning.load(tmp_path / "missing.npz", env)
    np.savez(tmp_path / "other.npz", weights=np.zeros(3))
    with pytest.raises(CheckpointError, match="not a readable"):
        QLearning.load(tmp_path / "other.npz", env)
    lake = gym.make("FrozenLake-v1")
    path = QLearning(lake).save(tmp_path / "lake.npz")
    with pytest.raises(CheckpointError, match=r"shape \(16, 4\).*\(750, 6\)"):
        QLearning.load(path, env)
    # A truncated file (a crash mid-copy) is reported, not half-read.
    good = QLearning(env).save(tmp_path / "good.npz")
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[:2000])
    with pytest.raises(CheckpointError):
        QLearning.load(cut, env)


def test_needs_discrete_spaces():
    with pytest.raises(TypeError, match="Discrete"):
        QLearning(gym.make("Pendulum-v1"))


def test_a_run_that_dies_after_learning_leaves_a_checkpoint_to_finish(tmp_path, monkeypatch):
    """The table is saved every log_interval episodes and before the motion is planned."""
    from aftir_rl.rl.tabular import train as tabular_train

    config = QLearningConfig(episodes=120, log_interval=50)
    target = [(230, 72, 10)]
    saved = []
    real_save = QLearning.save
    monkeypatch.setattr(
        QLearning,
        "save",
        lambda self, *a, **k: saved.append(self.episodes_done) or real_save(self, *a, **k),
    )

    def killed(*args, **kwargs):
        raise RuntimeError("killed while planning")

    monkeypatch.setattr(tabular_train, "log_greedy_path", killed)
    with pytest.raises(RuntimeError, match="killed"):
        tabular_train.train_q_table(config, target, logdir=tmp_path, progress_bar=False)
    assert saved == [50, 100, 120]
    (partial,) = tmp_path.iterdir()
    assert partial.name.endswith(".partial")
    assert QLearning.read_checkpoint(partial / "q_table.npz")[1]["episodes_done"] == 120

    monkeypatch.undo()  # finish it: nothing is left to learn, the motion is planned
    (summary,) = tabular_train.train_q_table(
        config, target, logdir=tmp_path, resume=partial, progress_bar=False, postures=False
    )
    finished = QLearning.read_checkpoint(f"{summary['run_dir']}/q_table.npz")
    env = gym.make("AFTIR-Tank-v0", target=target[0], max_episode_steps=config.max_episode_steps)
    straight = QLearning.from_config(env, config, seed=0).learn(120)
    np.testing.assert_array_equal(finished[0], straight.q_table)
    assert Path(summary["run_dir"]).is_dir()
