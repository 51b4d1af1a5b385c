"""``ArmRouteEnv``: the arm's route a section at a time, closed onto the target by the planner."""

from __future__ import annotations

import pickle
from dataclasses import replace

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.errors import ConfigError, InvalidActionError
from aftir_rl.envs.ftl import route_env
from aftir_rl.envs.ftl.env import ArmFTLEnv
from aftir_rl.envs.ftl.route_env import ROUTE_LEADS, ROUTE_SETTINGS, ArmRouteEnv
from aftir_rl.planning.ftl.plan import deploy_route
from aftir_rl.planning.ftl.route import move_set, plan_route, route_moves


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
    """The planner's route, a section at a time: from each route the env is at, the move
    nearest the next section of the planner's continuation (lead and sections kept); the env
    closes it onto the target, and the deployed motion keeps 1 cm by python-fcl at every
    posture."""
    env.reset(seed=seed)
    route = plan_route(env.tank, env.target, None, ROUTE_SETTINGS).route
    lead = int(np.argmin(np.abs(np.array(ROUTE_LEADS) - route.lead)))
    _, reward, terminated, _, info = env.step(lead)
    moves = move_set(ROUTE_SETTINGS)
    settings = replace(ROUTE_SETTINGS, leads=(ROUTE_LEADS[lead],))
    while not terminated:
        k = env.route.n_route_sections
        route = plan_route(
            env.tank, env.target, None, settings, env.arm, env.route if k else None
        ).route
        last = env.route.kappa[-1] if k else np.zeros(2)
        far = np.abs(moves + last - route.kappa[k]).sum(axis=1)
        _, reward, terminated, _, info = env.step(
            int(np.argmin(np.where(env.action_masks(), far, np.inf)))
        )
    assert info["is_success"], "the env closes the planner's route before its moves run out"
    assert reward == 1.0
    final = env.final_route()
    assert final is not None and np.linalg.norm(final.tip() - env.target) < 1e-4
    plan = env.motion()
    again = deploy_route(env.tank, env.target, final)
    assert plan is not None and plan.min_clearance_cm == again.min_clearance_cm
    scene = CollisionScene(env.tank, links_per_section=10)
    motion = plan.motion
    clearance = min(scene.check(motion.posture(t)).clearance_cm for t in range(len(motion)))
    assert plan.complete and clearance >= 1.0 - 0.05


def test_a_move_that_is_not_clear_ends_in_contact_and_restore_replays(env):
    env.reset(seed=11)
    obs, *_ = env.step(ROUTE_LEADS.index(0.0))
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


def test_the_first_action_chooses_the_lead(env):
    """At the first step the leads are the open actions, with their features in their slots;
    the chosen lead is the route's and is observed; one lead makes no such step."""
    first, _ = env.reset(seed=5)
    n, inner = len(ROUTE_LEADS), len(first) - 4 * 25 - 5
    assert env.choosing and env.action_masks().tolist() == [True] * n + [False] * (25 - n)
    assert first[-5] == 1.0
    _, reward, terminated, _, info = env.step(n)
    assert terminated and reward == -1.0 and info["not_a_lead"] and not info["contact"]
    for j, lead in enumerate(ROUTE_LEADS):
        env.restore(env.route, choosing=True)
        obs, _, terminated, _, _ = env.step(j)
        assert not env.choosing and env.route.lead == lead and env.route.n_route_sections == 0
        assert obs[-5] == 0.0 and obs[-4] == pytest.approx(lead / 100)
        np.testing.assert_allclose(obs[-3:], (env.target - env.route.tip()) / 100, atol=1e-6)
        ok = route_moves(env.tank, env.route, env.target, ROUTE_SETTINGS).ok
        assert terminated or (env.action_masks() == ok).all()
        assert first[inner + j] == ok.any()  # the lead's slot: whether a first section is clear
        assert first[inner + 75 + j] == pytest.approx(ok.mean())
    single = ArmRouteEnv(bay=2, leads=(0.0,))
    obs, _ = single.reset(seed=5)
    assert not single.choosing and obs[-5] == 0.0
    assert single.observation_space.contains(obs)
    for bad in ((), (0.0, float("nan")), tuple(range(26))):
        with pytest.raises(ConfigError, match="leads must be"):
            ArmRouteEnv(bay=2, leads=bad)


def test_each_version_has_its_leads_and_moves():
    """v1: 7 leads and moves changing κ by 1/3, 2/3 and all of 1.0 rad; v0 (registered with
    its kwargs): 5 leads and 0.75 rad. ``route_env`` makes either; nothing else is a version."""
    import gymnasium as gym

    from aftir_rl.envs.ftl.route_env import route_env

    for env_id, leads, change in [
        ("AFTIR-ArmRoute-v1", ROUTE_LEADS, 1.0),
        ("AFTIR-ArmRoute-v0", (-20.0, -10.0, 0.0, 15.0, 30.0), 0.75),
    ]:
        for env in (gym.make(env_id, bay=2).unwrapped, route_env(env_id, bay=2)):
            assert env.leads == leads and env.settings.max_change == change
            sizes = np.linalg.norm(env.moves, axis=1)
            np.testing.assert_allclose(
                sorted(set(np.round(sizes, 9))), [0, change / 3, 2 * change / 3, change]
            )
            assert env.observation_space.shape == (192,) and env.action_space.n == 25
    assert ROUTE_LEADS[:2] == (-40.0, -30.0)
    with pytest.raises(ConfigError, match="env_id must be one of"):
        route_env("AFTIR-ArmFTL-v0")
    for bad in (0, -1.0, 4.0, True, "1", float("nan")):
        with pytest.raises(ConfigError, match="max_change"):
            ArmRouteEnv(bay=2, max_change=bad)


def test_a_closing_whose_motion_loses_the_margin_is_not_a_success(env, monkeypatch):
    """The planner's route closes, but with its deployment refused the episode goes on."""
    env.reset(seed=3_000_000)
    route = plan_route(env.tank, env.target, None, ROUTE_SETTINGS).route
    real = route_env.deploy_route

    def refused(*args, **kwargs):
        plan = real(*args, **kwargs)
        plan.complete = False
        return plan

    monkeypatch.setattr(route_env, "deploy_route", refused)
    env.reset(seed=3_000_000)
    _, _, terminated, _, info = env.step(int(np.argmin(np.abs(np.array(ROUTE_LEADS) - route.lead))))
    moves = move_set(ROUTE_SETTINGS)
    for k in range(route.n_route_sections):
        if terminated:
            break
        last = route.kappa[k - 1] if k else np.zeros(2)
        move = int(np.argmin(np.abs(moves + last - route.kappa[k]).sum(axis=1)))
        _, _, terminated, _, info = env.step(move)
        assert env.motion() is None and env.final_route() is None
    assert not info["is_success"]


def test_a_stream_moves_on_to_the_next_wing_every_tank_episodes():
    """``tank="wing:2:F+"``: the same wings in the same order whatever the reset seeds; each
    episode's target, moves and observation are the new wing's (a clear move stays clear in
    it: route_moves asked of that wing directly)."""
    env = ArmRouteEnv(tank="wing:2:40+", tank_episodes=2, leads=(0.0,))
    met = []
    for seed in range(5):
        obs, info = env.reset(seed=100 + seed)
        met.append(info["tank"])
        assert env.tank.distance(env.target[None])[0] >= 5.0  # drawn in this wing
        assert env.observation_space.contains(obs)
        moves = route_moves(env.tank, env.route, env.target, ROUTE_SETTINGS)
        np.testing.assert_array_equal(env.action_masks(), moves.ok)
    assert met == ["wing:2:40", "wing:2:40", "wing:2:41", "wing:2:41", "wing:2:42"]
    assert env.tanks_met == 3


def test_a_pools_episode_uses_its_own_tank():
    env = ArmRouteEnv(tank="wing:2:40-41", leads=(0.0,))
    for k in (0, 1, 0):
        env.reset(seed=3, options={"tank": k})
        assert env.tank is env.inner.tank and env.tank.source == f"wing:2:{40 + k}"
        moves = route_moves(env.tank, env.route, env.target, ROUTE_SETTINGS, ahead=True)
        np.testing.assert_array_equal(env.action_masks(), moves.ok)


@pytest.mark.parametrize(
    "kwargs", [{"tank_episodes": 2}, {"tank": "wing:2:1+", "tank_episodes": 0},
               {"tank": "wing:2:1-3", "tank_episodes": 1}],
)  # fmt: skip
def test_tank_episodes_is_a_streams_count(kwargs):
    with pytest.raises(ConfigError, match="tank_episodes is a stream's"):
        ArmRouteEnv(**kwargs)


def test_a_stream_lets_go_of_the_wings_it_has_left():
    """Each wing's guide and clearance grid refer back to it: kept in weak-key caches they
    kept every wing a process met alive (12 GB after 200 wings). Past the loader's cache of
    the last few, a wing left behind is freed."""
    import gc
    import weakref

    env = ArmRouteEnv(tank="wing:2:60+", tank_episodes=1, leads=(0.0,))
    env.reset(seed=0)
    first = weakref.ref(env.tank)
    for seed in range(1, 6):  # the loader keeps the last 4 tanks: the first is let go
        env.reset(seed=seed)
    gc.collect()
    assert first() is None


def test_a_mixed_stream_meets_its_wings_in_order():
    from aftir_rl.envs.ftl.pool import stream_spec

    env = ArmRouteEnv(tank="mix:80+", tank_episodes=1, leads=(0.0,))
    stream = stream_spec("mix:80+")
    met = [env.reset(seed=s)[1]["tank"] for s in range(3)]
    assert met == [stream.spec_at(k) for k in range(3)]
    assert env.tank.source == met[-1] and env.observation_space.contains(env.observation())
