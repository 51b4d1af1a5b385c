"""Route policies: the planner as an online teacher, cloning, and the search at inference."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
import pytest
import torch

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.errors import CheckpointError, ConfigError
from aftir_rl.envs.ftl.route_env import ArmRouteEnv
from aftir_rl.rl.route_policy import (
    RoutePolicy,
    RouteTeacher,
    load_route_policy,
    route_search,
    save_route_policy,
    train_route_policy,
)
from aftir_rl.rl.tensors import save_tensors


@pytest.fixture(scope="module")
def env():
    return ArmRouteEnv(bay=2)


@pytest.fixture(scope="module")
def small(env):
    """A policy cloned from the teacher's routes to 4 training targets (about a second)."""
    torch.set_num_threads(1)
    return train_route_policy(env, routes=4, updates=100, seed=3)


@pytest.mark.parametrize("seed", [3_000_003, 3_000_004])
def test_the_teacher_followed_reaches_held_out_targets_and_its_motion_keeps_1cm(env, seed):
    """The teacher's actions, followed in the env, close the route; python-fcl at every
    posture of the motion (independent of the env's own check) finds 1 cm."""
    teacher = RouteTeacher()
    env.reset(seed=seed)
    assert teacher.finishes(env) and env.choosing  # put back where it was
    info = {"is_success": False}
    while (action := teacher(env)) is not None:
        _, _, terminated, _, info = env.step(action)
        if terminated:
            break
    assert info["is_success"] and teacher.queries >= teacher.answered > 0
    plan = env.motion()
    scene = CollisionScene(env.tank, links_per_section=10)
    motion = plan.motion
    least = min(scene.check(motion.posture(t)).clearance_cm for t in range(len(motion)))
    assert least >= 1.0 - 0.05
    assert np.linalg.norm(motion.tips()[-1] - env.target) < 2.0


def test_cloning_fits_the_teachers_labels_and_rounds_are_reported(env, small):
    policy, stats = small
    (row,) = stats.rounds
    assert row["round"] == 0 and row["states"] > 4 and row["train_accuracy"] > 0.5
    assert row["teacher"]["queries"] == stats.teacher.queries > 0
    with pytest.raises(ConfigError, match="routes and updates"):
        train_route_policy(env, routes=0)


def test_greedy_is_the_policys_first_choice_and_the_search_is_deterministic(env, small):
    policy, _ = small
    env.reset(seed=3_000_010)
    steps = 0
    while True:
        order = policy.order(env.observation(), env.action_masks())
        _, _, terminated, _, info = env.step(order[0])
        steps += 1
        if terminated:
            break
    greedy = route_search(env, policy, 3_000_010, 0)
    assert (greedy.success, greedy.steps) == (bool(info["is_success"]), steps)
    for seed in (3_000_011, 3_000_012):
        a, b = route_search(env, policy, seed, 40), route_search(env, policy, seed, 40)
        assert a == b and a.steps <= 40
        if a.success:
            plan = env.motion()
            assert plan is not None and plan.complete and plan.min_clearance_cm >= 1.0


def test_a_fixed_target_is_searched_for(env, small):
    policy, _ = small
    target = np.array([170.0, 80.0, 50.0])  # straight through the hatch
    result = route_search(env, policy, None, 60, target)
    np.testing.assert_array_equal(env.target, target)
    assert result.steps >= 1


def test_weights_round_trip_as_tensors_and_anything_else_is_refused(env, small, tmp_path):
    policy, _ = small
    path = save_route_policy(policy, tmp_path / "route.pt")
    back = load_route_policy(path)
    obs, _ = env.reset(seed=5)
    mask = env.action_masks()
    np.testing.assert_array_equal(back.log_probs(obs, mask), policy.log_probs(obs, mask))
    save_tensors({"n_obs": 10**9, "n_actions": 25, "net": {}}, tmp_path / "huge.pt")
    save_tensors({"n_obs": policy.n_obs + 1, "n_actions": 25}, tmp_path / "short.pt")
    other = {"n_obs": policy.n_obs + 1, "n_actions": 25, "net": policy.net.state_dict()}
    save_tensors(other, tmp_path / "other.pt")
    (tmp_path / "junk.pt").write_bytes(os.urandom(300))
    for name in ("huge", "short", "other", "junk"):
        with pytest.raises(CheckpointError, match="route policy's weights|not a readable tensor"):
            load_route_policy(tmp_path / f"{name}.pt")


class _Boom:
    def __reduce__(self):
        return (os.system, ("touch /tmp/aftir-route-pwned",))


def test_a_pickle_that_would_run_code_is_refused(tmp_path):
    buffer = io.BytesIO()
    torch.save({"n_obs": 5, "n_actions": 25, "net": _Boom()}, buffer, pickle_protocol=2)
    (tmp_path / "bad.pt").write_bytes(buffer.getvalue())
    Path("/tmp/aftir-route-pwned").unlink(missing_ok=True)
    with pytest.raises(CheckpointError, match="route policy's weights"):
        load_route_policy(tmp_path / "bad.pt")
    assert not Path("/tmp/aftir-route-pwned").exists()


@pytest.mark.slow
def test_a_cloned_policy_and_its_search_beat_the_same_search_without_learning(env):
    """80 training routes (about 30 s): on 30 held-out bay-2 targets the cloned policy's best-
    first search within 100 env steps reaches nearly all (measured 30; greedily 21), the same
    search under a uniform policy (every open action alike) none (measured 0)."""
    torch.set_num_threads(1)
    policy, _ = train_route_policy(env, routes=80, seed=0)
    uniform = RoutePolicy(policy.n_obs, policy.n_actions)
    for p in uniform.net.parameters():
        torch.nn.init.zeros_(p)
    seeds = range(3_100_000, 3_100_030)
    greedy = sum(route_search(env, policy, s, 0).success for s in seeds)
    search = sum(route_search(env, policy, s, 100).success for s in seeds)
    blind = sum(route_search(env, uniform, s, 100).success for s in seeds)
    assert search >= greedy and search >= 27 and search - blind >= 20, (greedy, search, blind)
