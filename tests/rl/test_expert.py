"""The planner as a teacher: route actions, the expert's motions, datasets and cloning."""

from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.errors import ConfigError
from aftir_rl.envs.ftl.env import ArmFTLEnv
from aftir_rl.planning.ftl.model import Route
from aftir_rl.rl.expert import EXPERT_SETTINGS, ExpertPolicy, FTLExpert, route_actions

KWARGS = {"bay": 2, "steer": "target", "guide": True, "shaping": "field", "step_cost": 0.02}


@pytest.mark.parametrize("steer", ["target", "increment"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_route_actions_deploy_the_route(steer, seed):
    """The env ends on the route: its κ history, and the tip forward kinematics gives."""
    rng = np.random.default_rng(seed)
    env = ArmFTLEnv(steer=steer, margin=0.0)
    env.reset(seed=seed)
    m = int(rng.integers(1, 7))
    kappa = rng.uniform(-0.8, 0.8, (m, 2))
    for a in route_actions(kappa, env):
        env.step(a)
    b = env.batch
    assert b.s[0] == pytest.approx(m * b.l)
    np.testing.assert_allclose(b.kappa[0, :m], kappa, atol=1e-6)
    np.testing.assert_allclose(env.tip, Route(0.0, kappa, b.l).tip(), atol=1e-3)


def test_route_actions_start_from_any_arm():
    """From a deployed arm they pull back to the floor first, then deploy the new route."""
    env = ArmFTLEnv(steer="target", margin=0.0)
    env.reset(seed=0)
    for a in route_actions([[0.3, 0.1], [-0.2, 0.4]], env):
        env.step(a)
    kappa = np.array([[0.1, -0.5], [0.6, 0.0], [0.0, 0.2]])
    actions = route_actions(kappa, env)
    assert (actions[:20, 2] == -1).all()  # 100 cm back, 5 cm a step
    for a in actions:
        env.step(a)
    np.testing.assert_allclose(env.tip, Route(0.0, kappa, env.batch.l).tip(), atol=1e-3)


# bay-2 targets: one the env drew (seed 5,000,003), a corner, right behind the baffle beside
# the hatch (the last two the expert may miss: the env's deployment between stages grazes there)
_TARGETS = [
    (28.94, 110.54, 26.0),
    pytest.param((230.0, 140.0, 90.0), marks=pytest.mark.slow),
    pytest.param((100.3, 81.7, 80.0), marks=pytest.mark.slow),
]


@pytest.mark.parametrize("target", _TARGETS)
def test_the_expert_reaches_a_target_without_contact(target):
    """Replayed in a fresh env: success, and python-fcl keeps the margin after every step.

    Or no motion at all within the budget: never one the env would end in contact.
    """
    import gymnasium as gym

    expert = FTLExpert(max_seconds=10.0, **KWARGS)
    plan = expert.plan(target)
    if plan is None:
        assert target != (28.94, 110.54, 26.0)
        return
    env = gym.make("AFTIR-ArmFTL-v0", **KWARGS)
    env.reset(options={"target": target})
    scene = CollisionScene(env.unwrapped.tank)
    for k, a in enumerate(plan.actions):
        _, _, term, trunc, info = env.step(a)
        assert scene.check(env.unwrapped.posture).clearance_cm >= 1.0
        assert not info["contact"] and not trunc
        assert term == (k == len(plan.actions) - 1)
    assert info["is_success"] and info["distance_cm"] < 2.0


def _replays_clear(plan, target):
    """Whether the env ends ``plan`` in success, python-fcl keeping the margin at every step."""
    import gymnasium as gym

    env = gym.make("AFTIR-ArmFTL-v0", **KWARGS)
    env.reset(options={"target": target})
    scene = CollisionScene(env.unwrapped.tank)
    least = np.inf
    for a in plan.actions:
        _, _, term, trunc, info = env.step(a)
        least = min(least, scene.check(env.unwrapped.posture).clearance_cm)
    return bool(term and info["is_success"] and not info["contact"]) and least >= 1.0


@pytest.mark.slow
def test_a_route_a_little_off_the_floor_is_replayed_from_it():
    """A target (reset seed 2,000,001) whose only clear route of the main search settings
    starts 0.31 cm below the floor: refused with ``max_lead=0``, replayed to success with the
    default 1 cm (the motion shifted up by 0.31 cm, the tip within tolerance)."""
    target = (153.40852063499338, 88.32054359939697, 50.93567738346021)
    main = EXPERT_SETTINGS[:6]
    assert FTLExpert(max_seconds=10.0, max_lead=0.0, settings=main, **KWARGS).plan(target) is None
    plan = FTLExpert(max_seconds=10.0, settings=main, **KWARGS).plan(target)
    assert plan is not None and _replays_clear(plan, target)


def _run_policy(env, policy, seed, pulls=(0, 0)):
    """An episode of ``policy`` (``pulls[1]`` pull-backs from step ``pulls[0]``, off its plan):
    the last info and python-fcl's least clearance over every step."""
    scene = CollisionScene(env.unwrapped.tank)
    obs, info = env.reset(seed=seed)
    least, start = np.inf, True
    for t in range(300):
        if pulls[0] <= t < pulls[0] + pulls[1]:  # keep the bend, pull back a step
            b = env.unwrapped.batch
            a = np.array([*(b.kappa[0, b.k[0]] / float(env.unwrapped.arm.theta_max)), -1.0])
        else:
            a, _ = policy.predict(obs, episode_start=np.array([start]))
        start = False
        obs, _, term, trunc, info = env.step(a.astype(np.float32))
        least = min(least, scene.check(env.unwrapped.posture).clearance_cm)
        if term or trunc:
            return info, least
    return info, least


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow), 2])
def test_the_expert_policy_recovers_when_taken_off_its_plan(seed):
    """Pulled back 1-6 steps at a random step of its motion (actions it did not choose), the
    policy notices, plans again from that arm and still ends in success with the margin kept
    (python-fcl after every step); left alone it never replans."""
    import gymnasium as gym

    rng = np.random.default_rng(seed)
    env = gym.make("AFTIR-ArmFTL-v0", **KWARGS)
    policy = ExpertPolicy(env)
    reset_seed = 2_000_000 + 3 * seed
    info, least = _run_policy(env, policy, reset_seed)
    assert info["is_success"] and least >= 1.0 and policy.replans == 0
    steps = int(rng.integers(5, 50))
    info, least = _run_policy(env, policy, reset_seed, (steps, int(rng.integers(1, 7))))
    assert info["is_success"] and not info["contact"] and least >= 1.0
    assert policy.replans == 1 and policy.fallbacks == 0


def test_the_expert_policy_falls_back_to_the_floor_without_a_plan():
    """An expert that finds no motion: it pulls the arm back to the floor (10 cm, 5 cm a step),
    plans once more there, and then holds."""
    import gymnasium as gym

    env = gym.make("AFTIR-ArmFTL-v0", **KWARGS)
    policy = ExpertPolicy(env, FTLExpert(settings=(), **KWARGS))
    env.reset(seed=0)
    pushes = []
    for _ in range(4):
        a, _ = policy.predict(None)
        env.step(a)
        pushes.append(float(a[2]))
    assert pushes == [-1.0, -1.0, 0.0, 0.0] and env.unwrapped.insertion == 0.0
    assert policy.fallbacks == 1


def test_an_expert_policy_refuses_an_expert_of_another_env():
    with pytest.raises(ConfigError, match="steering or steps are not the env's"):
        ExpertPolicy(ArmFTLEnv(steer="increment"), FTLExpert(**KWARGS))
    with pytest.raises(ConfigError, match="pass expert"):
        ExpertPolicy(ArmFTLEnv(**KWARGS))
    with pytest.raises(ConfigError, match="pool"):
        ExpertPolicy(ArmFTLEnv(tank="wing:2:0-1"))
    with pytest.raises(ConfigError, match="max_lead"):
        FTLExpert(max_lead=-1.0, **KWARGS)


@pytest.mark.slow
def test_the_expert_on_random_bay2_targets():
    """Random bay-2 targets of the env's own draw: the expert's motions all succeed."""
    import gymnasium as gym

    env = gym.make("AFTIR-ArmFTL-v0", **KWARGS)
    expert = FTLExpert(**KWARGS)
    found = 0
    for seed in range(6_000_000, 6_000_008):
        _, info = env.reset(seed=seed)
        plan = expert.plan(info["target"])
        if plan is None:
            continue
        found += 1
        for a in plan.actions:
            _, _, term, _, step = env.step(a)
        assert term and step["is_success"] and not step["contact"]
    assert found >= 7


def test_bad_dataset_ids_and_paths_are_one_line(tmp_path):
    from aftir_rl.rl.demos import write_dataset
    from aftir_rl.rl.imitation import load_demos

    for bad in ("../../etc/x-v0", "aftir/x", "/abs/x-v0", "a/b/c-v0"):
        with pytest.raises(ConfigError, match="dataset id") as info:
            write_dataset(tmp_path, 1, dataset_id=bad)
        assert "\n" not in str(info.value)
    with pytest.raises(ConfigError, match="not a Minari dataset"):
        load_demos(tmp_path, 0.99)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from aftir_rl.rl.demos import write_dataset

    root = tmp_path_factory.mktemp("datasets")
    out = write_dataset(root, 2, seed=8_000_000, env_kwargs=KWARGS)
    return root, out


@pytest.mark.slow
def test_a_dataset_holds_the_env_episodes_and_resumes(dataset, capsys):
    import minari

    from aftir_rl.cli import dataset as dataset_cli
    from aftir_rl.rl.demos import write_dataset

    root, out = dataset
    assert out["episodes"] == 2 and out["steps"] > 100
    data = minari.load_dataset(out["dataset_id"])
    assert data.total_episodes == 2 and data.spec.env_spec.kwargs == KWARGS
    env = data.recover_environment()
    for episode in data.iterate_episodes():
        assert episode.terminations[-1] and not episode.terminations[:-1].any()
        for key, space in env.observation_space.spaces.items():
            assert episode.observations[key].shape == (len(episode.actions) + 1, *space.shape)
        # the relabelled reward HER would compute is the recorded one
        rewards = env.unwrapped.compute_reward(
            episode.observations["achieved_goal"][1:],
            episode.observations["desired_goal"][1:],
            [
                {"prev_achieved_goal": p, "contact": c}
                for p, c in zip(
                    episode.infos["prev_achieved_goal"][1:], episode.infos["contact"][1:]
                )
            ],
        )
        np.testing.assert_allclose(rewards, episode.rewards, atol=1e-4)
    again = write_dataset(root, 3, seed=8_000_000, env_kwargs=KWARGS)
    assert again["episodes"] == 3 and minari.load_dataset(out["dataset_id"]).total_episodes == 3
    assert again["before"] == 2 and again["steps"] > 0
    capsys.readouterr()  # the default config's env_kwargs are KWARGS: a rerun adds nothing
    assert dataset_cli.main(["--episodes", "3", "-o", str(root), "--no-progress"]) == 0
    printed = capsys.readouterr()
    assert json.loads(printed.out)["steps"] == 0
    assert "already holds 3 episodes (3 asked): nothing added" in printed.err
    with pytest.raises(ConfigError, match="other env arguments"):
        write_dataset(root, 4, env_kwargs={**KWARGS, "bay": 1})


@pytest.mark.slow
def test_cloning_fits_the_experts_actions(dataset, tmp_path):
    """The cloned policy's deterministic actions are much nearer the expert's than before."""
    from aftir_rl.rl.imitation import clone, load_demos
    from aftir_rl.rl.sb3 import build_model, entry_config
    from aftir_rl.rl.sb3.vec_adapter import make_sb3_vec_env

    root, out = dataset
    demos = load_demos(root / out["dataset_id"], 0.995)
    config = entry_config("ppo", "AFTIR-ArmFTL-v0")
    venv = make_sb3_vec_env("AFTIR-ArmFTL-v0", 2, **KWARGS)
    model = build_model("ppo", config, venv, seed=0)
    first = clone(model, demos, epochs=1, learning_rate=0.0)  # measures only
    fitted = clone(model, demos, epochs=60, batch_size=64)
    assert fitted["action_mse"] < 0.3 * first["action_mse"]
    assert fitted["steps"] == len(demos.actions)  # every step of every episode on disk
    with pytest.raises(ConfigError, match="steer"):
        from aftir_rl.rl.imitation import pretrainer

        pretrainer(root / out["dataset_id"], config)  # the entry steers by increments


@pytest.mark.parametrize(
    "args, says",
    [
        (["sac", "--env", "AFTIR-ArmFTL-v0", "--demos", "x"], "starts a new PPO run"),
        (["ppo", "--config", "ppo_ftl_demos", "--demos", "x", "--resume", "r"], "new PPO run"),
        (["ppo", "--config", "ppo_ftl_curriculum", "--demos", "x"], "new PPO run"),
        (["ppo", "--config", "ppo_ftl_demos", "--demos", "/nonexistent"], "not a Minari"),
    ],
)
def test_bad_demos_are_one_line_before_training(args, says, tmp_path, capsys):
    from aftir_rl.cli import train

    assert train.main([*args, "--logdir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and "\n" not in err
    assert list(tmp_path.iterdir()) == []


def test_aftir_dataset_refuses_bad_input_in_one_line(tmp_path, capsys):
    from aftir_rl.cli import dataset

    for argv, says in [
        (["--episodes", "0", "-o", str(tmp_path)], "--episodes"),
        (["--episodes", "1", "-o", str(tmp_path), "--id", "../x-v0"], "dataset id"),
        (
            [
                "--episodes",
                "1",
                "-o",
                str(tmp_path),
                "--config",
                "ppo_ftl",
                "--env-kwargs",
                "bay:9",
            ],
            "bay",
        ),
        (["--episodes", "1", "-o", str(tmp_path), "--max-seconds", "0"], "--max-seconds"),
    ]:
        assert dataset.main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert says in err and "\n" not in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "edit, says",
    [
        (lambda e: e.__setattr__("actions", e.actions * np.nan), "episode 1: actions holds a NaN"),
        (
            lambda e: e.__setattr__("actions", e.actions[:, :2]),
            "expected actions (T, 3)",
        ),
        (lambda e: e.__setattr__("actions", None), "episode 1: actions is not an array"),
        (lambda e: e.observations.pop("desired_goal"), "episode 1: observations must be a dict"),
        (lambda e: e.__setattr__("rewards", e.rewards * np.inf), "episode 1: rewards holds"),
        (lambda e: e.__setattr__("rewards", e.rewards * 1e300), "episode 1: rewards sum to"),
        (
            lambda e: e.observations.__setitem__("observation", e.observations["observation"][:3]),
            "observations['observation'] must hold T + 1",
        ),
    ],
)
def test_corrupt_demonstrations_are_one_line(tmp_path, monkeypatch, edit, says):
    """Every episode of a dataset is checked before any cloning: the episode and the field named."""
    import types

    import minari

    from aftir_rl.rl.imitation import load_demos

    def episode():
        obs = {k: np.zeros((6, n)) for k, n in (("observation", 87), ("desired_goal", 3))}
        return types.SimpleNamespace(observations=obs, actions=np.zeros((5, 3)), rewards=np.ones(5))

    episodes = [episode(), episode()]
    edit(episodes[1])
    fake = types.SimpleNamespace(iterate_episodes=lambda: iter(episodes), spec=None)
    monkeypatch.setattr(minari, "load_dataset", lambda name: fake)
    (tmp_path / "aftir" / "demo-v0" / "data").mkdir(parents=True)
    with pytest.raises(ConfigError, match=re.escape(says)) as info:
        load_demos(tmp_path / "aftir" / "demo-v0", 0.99)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("make", ["fifo", "link", "big", "folder"])
def test_dataset_files_that_would_block_or_flood_are_refused_first(tmp_path, make):
    """A FIFO (Minari's open would block), a link, a sparse giant or a folder in data/."""
    from aftir_rl.rl.imitation import MAX_METADATA_BYTES, load_demos

    data = tmp_path / "aftir" / "demo-v0" / "data"
    data.mkdir(parents=True)
    (data / "main_data.hdf5").write_bytes(b"")
    meta = data / "metadata.json"
    if make == "fifo":
        os.mkfifo(meta)
    elif make == "link":
        meta.symlink_to(tmp_path / "elsewhere.json")
    elif make == "big":
        with open(meta, "wb") as fh:
            fh.truncate(MAX_METADATA_BYTES + 1)
    else:
        meta.mkdir()
    with pytest.raises(ConfigError, match="metadata.json: (not a regular file|1,000,001 bytes)"):
        load_demos(data.parent, 0.99)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_teacher_continues_a_learners_whole_sections(seed):
    """From an arm a noisy expert left mid-way, the continuation keeps its whole sections.

    The arm: the expert's motion to a bay-2 target the env draws, played with its steering
    perturbed, stopped at a random step. The continuation is replayed in a fresh env from that
    arm: it succeeds with python-fcl's clearance at least the margin after every step, never
    pulls the tip behind the end of the arm's whole sections, and its route starts with them.
    """
    expert = FTLExpert(max_seconds=10.0, **KWARGS)
    env = ArmFTLEnv(**KWARGS)
    rng = np.random.default_rng(seed)
    for draw in range(20):  # a start whose noisy play survives with a whole section or more
        env.reset(seed=1000 * seed + draw)
        target = env.target.copy()
        plan = expert.plan(target)
        if plan is None:
            continue
        env.reset(seed=1000 * seed + draw)
        stop = int(rng.integers(len(plan.actions) // 3, len(plan.actions)))
        alive = True
        for a in plan.actions[:stop]:
            noisy = np.clip(a + np.r_[rng.normal(0.0, 0.08, 2), 0.0], -1.0, 1.0)
            alive = not any(env.step(noisy.astype(np.float32))[2:4])
            if not alive:
                break
        if alive and env.batch.k[0] > 0:
            break
    else:
        pytest.fail("no noisy play kept a whole section")
    kappa, k, s = env.route_kappa, int(env.batch.k[0]), env.insertion
    more = expert.continue_plan(target, env)
    assert more is not None
    np.testing.assert_array_equal(more.route_kappa[:k], kappa[:k])
    scene = CollisionScene(env.tank)
    least_s = s
    for a in more.actions:
        _, _, term, trunc, info = env.step(a)
        least_s = min(least_s, env.insertion)
        assert scene.check(env.posture).clearance_cm >= 1.0 and not info["contact"]
    assert term and info["is_success"] and least_s >= k * env.batch.l - 1e-9


def test_a_crowded_data_folder_still_has_minaris_files_checked(tmp_path):
    """Entries sorted before them do not hide a FIFO where Minari reads its data."""
    from aftir_rl.rl.imitation import load_demos

    data = tmp_path / "aftir" / "demo-v0" / "data"
    data.mkdir(parents=True)
    for i in range(150):
        (data / f"a{i:03d}").write_bytes(b"")
    (data / "metadata.json").write_text("{}")
    os.mkfifo(data / "main_data.hdf5")
    with pytest.raises(ConfigError, match="main_data.hdf5: not a regular file"):
        load_demos(data.parent, 0.99)
