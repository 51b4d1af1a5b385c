from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from aftir_rl.cli import train
from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.errors import InvalidActionError, TargetError

ARM_IDS = ["AFTIR-ArmReach-v0", "AFTIR-Arm-v0"]


@pytest.mark.parametrize("env_id", ARM_IDS)
def test_long_random_rollout_stays_in_space(env_id):
    env = gym.make(env_id)
    env.reset(seed=1)
    env.action_space.seed(1)
    episodes = 0
    for _ in range(1500):
        obs, reward, term, trunc, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs) and np.all(np.isfinite(obs))
        assert np.isfinite(reward)
        if term or trunc:
            episodes += 1
            obs, _ = env.reset()
            assert env.observation_space.contains(obs)
    assert episodes > 5


def test_collisions_agree_with_the_collision_module():
    env = gym.make("AFTIR-Arm-v0").unwrapped
    scene = CollisionScene(env.tank, links_per_section=5)
    rng = np.random.default_rng(0)
    seen = {True: 0, False: 0}
    env.reset(seed=0)
    for _ in range(600):
        _, _, term, _, info = env.step(rng.uniform(-1, 1, env.action_space.shape))
        assert info["collision"] == scene.check(env.posture).collides
        seen[info["collision"]] += 1
        if term:
            env.reset()
    # Pushing the straight arm up runs it into the ceiling.
    env.reset(seed=1)
    push = np.zeros(env.action_space.shape, dtype=np.float32)
    push[0] = 1.0
    for _ in range(60):
        _, reward, term, _, info = env.step(push)
        assert info["collision"] == scene.check(env.posture).collides
        if term:
            break
    assert info["collision"] and reward < -9
    assert seen[True] >= 1 and seen[False] > 100


def test_target_options_success_and_errors():
    env = gym.make("AFTIR-ArmReach-v0").unwrapped
    obs, info = env.reset(seed=0, options={"target": (0.0, 0.0, 12.0)})
    np.testing.assert_allclose(info["target"], [0, 0, 12])
    # The straight arm starts with its tip at (0, 0, 10): raising it 2 cm reaches the target.
    _, reward, term, _, info = env.step(np.r_[1.0, np.zeros(4)].astype(np.float32) * (2 / 3))
    assert term and info["is_success"] and reward > 10
    with pytest.raises(TargetError):
        env.reset(options={"target": (0.0, 20.0, 85.0)})  # inside a pipe
    with pytest.raises(InvalidActionError):
        env.step(np.zeros(3, dtype=np.float32))
    with pytest.raises(InvalidActionError):
        env.step(np.full(5, np.nan, dtype=np.float32))


def test_render():
    env = gym.make("AFTIR-ArmReach-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.std() > 10


@pytest.mark.parametrize(
    "algo, steps",
    [
        # the fast tier trains PPO through the CLI on the batched env (test_ftl_batch.py) and
        # SAC+HER on AFTIR-ArmFTL-v0 (test_arm_ftl.py)
        pytest.param("ppo", 256, marks=pytest.mark.slow),
        pytest.param("sac", 200, marks=pytest.mark.slow),
        pytest.param("td3", 200, marks=pytest.mark.slow),
    ],
)
def test_smoke_training_writes_tensorboard(tmp_path, algo, steps, capsys):
    config = tmp_path / f"{algo}.yaml"
    hyper = (
        "  n_steps: 128\n  batch_size: 64\n"
        if algo == "ppo"
        # 50 small gradient steps: the loop and its TensorBoard files, not learning
        else "  learning_starts: 150\n  batch_size: 32\n  buffer_size: 1000\n"
        "  policy_kwargs:\n    net_arch: [32, 32]\n"
    )
    config.write_text(
        "env_id: AFTIR-ArmReach-v0\neval_freq: 100000\neval_targets: 2\ncheckpoint_freq: 100\n"
        f"hyperparameters:\n{hyper}"
    )
    rc = train.main(
        [
            algo,
            "--config",
            str(config),
            "--total-timesteps",
            str(steps),
            "--logdir",
            str(tmp_path / "runs"),
            "--no-progress",
        ]
    )
    assert rc == 0
    (run_dir,) = list((tmp_path / "runs").iterdir())
    assert (run_dir / "model.zip").exists() and any((run_dir / "checkpoints").iterdir())
    acc = EventAccumulator(str(run_dir), size_guidance={"images": 0, "tensors": 0})
    acc.Reload()
    tags = acc.Tags()
    for tag in (
        "eval/success_rate",
        "eval/tip_error_cm",
        "eval/path_length_cm",
        "eval/collision_rate",
    ):
        assert tag in tags["scalars"], tag
    assert "paths/eval" in tags["images"]
    # Resume from the saved model (with the default progress bar, which needs tqdm and rich),
    # and a corrupt model is a clean error.
    again = [algo, "--config", str(config), "--total-timesteps", "64", "--resume", str(run_dir)]
    rc = train.main([*again, "--logdir", str(tmp_path / "again")])
    assert rc == 0
    bad = tmp_path / "bad.zip"
    bad.write_bytes(b"not a zip")
    capsys.readouterr()
    rc = train.main(
        [
            algo,
            "--config",
            str(config),
            "--resume",
            str(bad),
            "--logdir",
            str(tmp_path / "x"),
            "--no-progress",
        ]
    )
    assert rc == 2 and "not a readable" in capsys.readouterr().err


def test_unknown_env_id_is_a_clean_error(tmp_path, capsys):
    assert train.main(["ppo", "--env", "Nope-v0", "--logdir", str(tmp_path)]) == 2
    assert "use one of AFTIR-ArmReach-v0, AFTIR-Arm-v0" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_bad_sb3_config(tmp_path, capsys):
    config = tmp_path / "ppo.yaml"
    config.write_text("env_id: AFTIR-ArmReach-v0\nhyperparameters:\n  learnin_rate: 0.1\n")
    assert train.main(["ppo", "--config", str(config), "--logdir", str(tmp_path)]) == 2
    assert "unknown key 'learnin_rate' for PPO" in capsys.readouterr().err


def test_full_arm_raw_joint_env_poses_the_ftl_task():
    """AFTIR-ArmFull-v0: 12 sections by joint increments, targets drawn as AFTIR-ArmFTL-v0's."""
    from gymnasium.utils.env_checker import check_env as gym_check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    from aftir_rl.core.collision import point_clearance

    env = gym.make("AFTIR-ArmFull-v0", bay=2)
    gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped)
    full, ftl = env.unwrapped, gym.make("AFTIR-ArmFTL-v0", bay=2).unwrapped
    assert full.n == 12 and full.action_space.shape == (25,)
    for seed in range(5):
        full.reset(seed=seed)
        ftl.reset(seed=seed)
        # the same task, target by target (the FTL env keeps them as float32 values)
        np.testing.assert_array_equal(full.target.astype(np.float32), ftl.target)
        assert point_clearance(full.tank, full.target[None])[0] >= 10.0
        assert full.target[full.tank.baffle.index] > full.tank.baffle.position
