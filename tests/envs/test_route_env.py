"""``ArmRouteEnv``: the arm's route a section at a time, closed onto the target by the planner."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.errors import InvalidActionError
from aftir_rl.envs.ftl.env import ArmFTLEnv
from aftir_rl.envs.ftl.route_env import ROUTE_SETTINGS, ArmRouteEnv
from aftir_rl.planning.ftl.plan import deploy_route
from aftir_rl.planning.ftl.route import move_set, plan_route


@pytest.fixture(scope="module")
def env():
    return ArmRouteEnv(bay=2)


def test_the_gymnasium_checks_pass_and_it_pickles(env):
    check_env(ArmRouteEnv(bay=2), skip_render_check=True)
    env.reset(seed=4)
    clone = pickle.loads(pickle.dumps(env))
    move = int(np.flatnonzero(env.action_masks())[0])
    a, b = env.step(move), clone.step(move)
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1:4] == b[1:4]


def test_targets_are_the_ftl_envs_for_the_same_seeds(env):
    ftl = ArmFTLEnv(bay=2)
    for seed in (0, 7, 3_000_000):
        env.reset(seed=seed)
        ftl.reset(seed=seed)
        np.testing.assert_array_equal(env.target, ftl.target)


@pytest.mark.parametrize("seed", [3_000_000, 3_000_001, 3_000_002])
def test_the_planners_moves_reach_the_target_and_its_motion_keeps_the_margin(env, seed):
    """The planner's own route, its moves taken one by one: the env closes it onto the target,
    and the deployed motion keeps 1 cm by python-fcl at every posture."""
    env.reset(seed=seed)
    route = plan_route(env.tank, env.target, None, ROUTE_SETTINGS).route
    moves = move_set(ROUTE_SETTINGS)
    info = {"is_success": False}
    for k in range(route.n_route_sections):
        last = route.kappa[k - 1] if k else np.zeros(2)
        move = int(np.argmin(np.abs(moves + last - route.kappa[k]).sum(axis=1)))
        if not env.action_masks()[move]:
            break  # the route's last sections come from the closing, not from moves
        _, reward, terminated, truncated, info = env.step(move)
        if terminated or truncated:
            break
    assert info["is_success"], "the env closes the planner's route before its moves run out"
    assert reward == 1.0
    final = env.final_route()
    assert final is not None and np.linalg.norm(final.tip() - env.target) < 1e-4
    plan = deploy_route(env.tank, env.target, final)
    scene = CollisionScene(env.tank, links_per_section=10)
    motion = plan.motion
    clearance = min(scene.check(motion.posture(t)).clearance_cm for t in range(len(motion)))
    assert plan.complete and clearance >= 1.0 - 0.05


def test_a_move_that_is_not_clear_ends_in_contact_and_restore_replays(env):
    obs, _ = env.reset(seed=11)
    start = env.route
    blocked = np.flatnonzero(~env.action_masks())
    clear = np.flatnonzero(env.action_masks())
    assert len(clear)
    after, *_ = env.step(int(clear[0]))
    env.restore(start)
    np.testing.assert_array_equal(env.observation(), obs)
    again, *_ = env.step(int(clear[0]))
    np.testing.assert_array_equal(again, after)
    with pytest.raises(InvalidActionError, match="a move 0 to 24"):
        env.step(25)
    if len(blocked):
        env.restore(start)
        _, reward, terminated, _, info = env.step(int(blocked[0]))
        assert terminated and info["contact"] and reward == -1.0
