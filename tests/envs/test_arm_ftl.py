"""AFTIR-ArmFTL-v0: the follow-the-leader arm env, its goal interface and its batched version."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from aftir_rl.core.collision import point_clearance
from aftir_rl.core.errors import AftirError, ConfigError, InvalidActionError, TargetError
from aftir_rl.core.robot import body_points
from aftir_rl.core.tank import TankDistance
from aftir_rl.envs.ftl.env import ArmFTLEnv
from aftir_rl.envs.ftl.fields import field_guide, raster_detour_table
from aftir_rl.envs.ftl.kernel import CONTACT_PENALTY
from aftir_rl.envs.ftl.spec import MAX_STEP_COST
from aftir_rl.envs.ftl.state import ftl_kappa_batch
from aftir_rl.planning.ftl.model import Route, ftl_postures, kappa_to_angles, route_points

ENV_ID = "AFTIR-ArmFTL-v0"


def rollout(env, actions, seed):
    """Observations, rewards, flags and infos of a rollout (resetting when an episode ends)."""
    obs, _ = env.reset(seed=seed)
    out = []
    for a in actions:
        nxt, r, term, trunc, info = env.step(a)
        out.append((obs, a, nxt, r, term, trunc, info))
        obs = nxt
        if term or trunc:
            obs, _ = env.reset()
    return out


@pytest.mark.parametrize(
    "kwargs",
    [
        {},
        {"bay": 2, "shaping": True},
        {"n_sections": 7},
        {"guide": True, "shaping": "field", "steer": "target"},
        {"guide": True, "shaping": "field", "steer": "target", "near_goal": True},
    ],
)
def test_env_checkers(kwargs):
    env = gym.make(ENV_ID, **kwargs)
    gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=True)


def test_spaces_and_registration():
    env = gym.make(ENV_ID)
    assert env.spec.max_episode_steps == 300
    assert env.action_space == gym.spaces.Box(-1, 1, (3,), np.float32)
    assert set(env.observation_space.spaces) == {"observation", "achieved_goal", "desired_goal"}
    obs, info = env.reset(seed=0)
    np.testing.assert_allclose(obs["achieved_goal"], [0, 0, 10], atol=1e-9)
    np.testing.assert_allclose(obs["desired_goal"], info["target"], atol=1e-4)
    assert env.unwrapped.batch.n == 12


@pytest.mark.parametrize(
    "shaping, guide", [(False, False), (True, False), ("field", False), ("field", True)]
)
def test_compute_reward_matches_step_rewards_in_batches(shaping, guide):
    env = gym.make(ENV_ID, shaping=shaping, guide=guide, max_episode_steps=60)
    rng = np.random.default_rng(1)
    # Push in mostly, so that the rollouts bend, touch and sometimes succeed.
    actions = rng.uniform(-1, 1, (400, 3)).astype(np.float32)
    actions[:, 2] = np.abs(actions[:, 2])
    steps = rollout(env, actions, seed=2)
    achieved = np.array([s[2]["achieved_goal"] for s in steps])
    desired = np.array([s[2]["desired_goal"] for s in steps])
    infos = np.array([s[6] for s in steps], dtype=object)
    rewards = np.array([s[3] for s in steps])
    base = env.unwrapped
    np.testing.assert_array_equal(base.compute_reward(achieved, desired, infos), rewards)
    assert any(s[6]["contact"] for s in steps)  # the penalty is exercised
    # Relabelled goals (what HER does): the batch equals row-by-row calls.
    goals = achieved[rng.permutation(len(achieved))]
    batch = base.compute_reward(achieved, goals, infos)
    single = [base.compute_reward(a, g, i) for a, g, i in zip(achieved, goals, infos)]
    np.testing.assert_array_equal(batch, single)
    # A goal equal to the achieved tip is a success unless there was contact.
    same = base.compute_reward(achieved, achieved, infos)
    contact = np.array([i["contact"] for i in infos])
    assert np.all(same[~contact] >= 10.0 - 1.0)
    terminated = base.compute_terminated(achieved, desired, infos)
    np.testing.assert_array_equal(terminated, [s[4] for s in steps])


def test_step_cost_is_paid_on_every_step_and_bounded():
    rng = np.random.default_rng(3)
    actions = rng.uniform(-1, 1, (150, 3)).astype(np.float32)
    actions[:, 2] = np.abs(actions[:, 2])
    plain = rollout(gym.make(ENV_ID, max_episode_steps=40), actions, seed=4)
    env = gym.make(ENV_ID, max_episode_steps=40, step_cost=0.02)
    costed = rollout(env, actions, seed=4)
    for a, b in zip(plain, costed):  # the same transitions, each reward 0.02 lower
        np.testing.assert_array_equal(a[2]["achieved_goal"], b[2]["achieved_goal"])
        assert a[4:6] == b[4:6]
        assert b[3] == pytest.approx(a[3] - 0.02, abs=1e-12)
    assert any(s[4] for s in costed)  # episodes ended on contact or success, not only by time
    achieved = np.array([s[2]["achieved_goal"] for s in costed])
    desired = np.array([s[2]["desired_goal"] for s in costed])
    infos = np.array([s[6] for s in costed], dtype=object)
    np.testing.assert_array_equal(
        env.unwrapped.compute_reward(achieved, desired, infos), [s[3] for s in costed]
    )
    # 300 steps of the largest cost stay below the contact penalty: touching never pays
    assert 300 * MAX_STEP_COST < CONTACT_PENALTY
    for bad in (-0.01, 0.031, float("nan"), "0.01", True):
        with pytest.raises(ConfigError, match="step_cost"):
            ArmFTLEnv(step_cost=bad)


def test_compute_reward_without_infos_is_an_error():
    env = gym.make(ENV_ID).unwrapped
    with pytest.raises(AftirError, match="copy_info_dict"):
        env.compute_reward(np.zeros((2, 3)), np.ones((2, 3)), [{}, {}])


def test_shaping_rewards_the_way_through_the_hatch():
    env = gym.make(ENV_ID, shaping=True).unwrapped
    target = np.array([[-50.0, 140.0, 90.0]])  # a reference target, far corner of bay 2
    detour = env.reward.potential
    # In bay 1, left of the hatch: out to the hatch and back, 2 x 6 cells (x) + 2 x 1 (z: the
    # hatch is at mid height, c = 2, the start and target cells at c = 1 and c = 4) ...
    assert detour(np.array([[-40.0, 0.0, 20.0]]), target)[0] == 20.0 * 12
    # ... which shrinks as the tip goes towards the hatch and vanishes past it.
    assert detour(np.array([[60.0, 40.0, 50.0]]), target)[0] == 20.0 * 2
    assert detour(np.array([[90.0, 40.0, 50.0]]), target)[0] == 0.0
    assert detour(np.array([[100.0, 70.0, 50.0]]), target)[0] == 0.0
    # Same bay: nothing in the way.
    assert detour(np.array([[-40.0, 0.0, 20.0]]), np.array([[200.0, 30.0, 60.0]]))[0] == 0


def test_field_shaping_pays_the_guide_fields_progress():
    """With ``shaping="field"`` progress plus shaping is the progress along the guide field's
    cost-to-go ``P``: over any rollout the non-terminal rewards sum to ``(P_start − P_end)/10``."""
    env = gym.make(ENV_ID, shaping="field", bay=2, max_episode_steps=40).unwrapped
    fields = field_guide(env.tank)  # the reward's: one guide per tank
    rng = np.random.default_rng(3)
    checked = 0
    for seed in range(3):
        obs, info = env.reset(seed=seed)
        target = info["target"][None]
        ids = fields.field_ids(target)
        start = fields(obs["achieved_goal"][None].astype(float), target, ids)[0][0]
        total = 0.0
        for _ in range(12):  # 60 cm in, bending a little: no contact, no success
            a = np.array([*rng.uniform(-0.3, 0.3, 2), 1.0], dtype=np.float32)
            obs, r, term, _, info = env.step(a)
            if term:
                break
            total += r
        if term:
            continue
        end = fields(env.batch.tip.copy(), target, ids)[0][0]
        assert total == pytest.approx((start - end) / 10, abs=1e-6)
        checked += 1
    assert checked >= 2  # the sums were compared, not skipped
    # the cost-to-go through the hatch: a tip in bay 1 beside the hatch is nearer than one
    # straight below a target behind the baffle, though the straight line says otherwise
    target = np.array([[0.0, 110.0, 50.0]])
    ids = fields.field_ids(target)
    near_hatch, below = np.array([[100.0, 40.0, 50.0]]), np.array([[0.0, 40.0, 50.0]])
    assert fields(near_hatch, target, ids)[0] < fields(below, target, ids)[0]
    with pytest.raises(ConfigError, match="shaping"):
        gym.make(ENV_ID, shaping="euclid")


def test_steer_target_approaches_the_named_bend_at_the_same_rate():
    env = gym.make(ENV_ID, steer="target").unwrapped
    env.reset(seed=0)
    batch, theta_max, step = env.batch, env.arm.theta_max, env.batch.kappa_step
    want = np.array([0.5, -0.25]) * theta_max
    path = []
    for _ in range(12):
        env.step(np.array([0.5, -0.25, 0.0], dtype=np.float32))
        path.append(batch.kappa[0, batch.k[0]].copy())
    path = np.array(path)
    moves = np.abs(np.diff(np.vstack([[0.0, 0.0], path]), axis=0))
    assert moves.max() <= step + 1e-12  # no faster than the increments
    np.testing.assert_allclose(path[-1], want, atol=1e-12)  # and it holds the bend
    assert np.ceil(np.abs(want).max() / step) <= 12
    # a corner of the action box names the largest bend on the diagonal
    for _ in range(40):
        env.step(np.array([1.0, 1.0, 0.0], dtype=np.float32))
    np.testing.assert_allclose(batch.kappa[0, batch.k[0]], [theta_max / np.sqrt(2)] * 2)
    with pytest.raises(ConfigError, match="steer"):
        gym.make(ENV_ID, steer="rate")


def test_raster_detour_table_against_bfs(tank):
    table = raster_detour_table(tank)
    raster = tank.raster
    rng = np.random.default_rng(0)
    free = np.argwhere(~raster.obstructed)
    cells = np.indices(raster.shape).reshape(3, -1).T
    for src in free[rng.choice(len(free), 5, replace=False)]:
        bfs = raster.bfs_distances(src).reshape(-1)
        manhattan = np.abs(cells - src).sum(1)
        ok = bfs >= 0
        np.testing.assert_array_equal(table[raster.index(src)][ok], (bfs - manhattan)[ok])


def test_ftl_kappa_batch_is_ftl_postures():
    rng = np.random.default_rng(0)
    n, l = 12, 50.0
    for _ in range(20):
        k = int(rng.integers(0, n))
        kappa = rng.uniform(-0.8, 0.8, (n, 2))
        s = rng.uniform(0, (k + 1) * l, 6)
        _, theta, phi = ftl_postures(Route(0.0, kappa[: k + 1], l), n, s)
        got = ftl_kappa_batch(np.repeat(kappa[None], 6, 0), np.full(6, k), s, l)
        th, ph = kappa_to_angles(got)
        np.testing.assert_allclose(th, theta, atol=1e-12)
        np.testing.assert_allclose(np.where(th > 1e-9, ph, 0.0), np.where(theta > 1e-9, phi, 0))


def test_body_at_whole_section_stages_lies_on_the_traced_route():
    env = gym.make(ENV_ID, start_height=0.0, max_episode_steps=500).unwrapped
    env.reset(seed=0, options={"target": (100.0, 30.0, 60.0)})
    base = env.batch
    stages = 0
    for i in range(60):  # push 5 cm a step: a whole-section stage every 10 steps
        # bend over (0.8 rad a section) under the ceiling, then straighten and turn aside
        steer = (1.0, 0.0) if i < 8 else (-1.0, 0.2) if 20 <= i < 28 else (0.0, 0.0)
        env.step(np.array([*steer, 1.0], dtype=np.float32))
        if base.contact[0]:
            break
        s = env.insertion
        if np.isclose(s % 50.0, 0.0) and s > 0:
            stages += 1
            k = int(round(s / 50.0))
            route = Route(0.0, env.route_kappa[:k], 50.0)
            dis, theta, phi = ftl_postures(route, 12, [s])
            pts = body_points(dis[0], theta[0], phi[0], 50.0, 10)
            u = dis[0] + np.arange(pts.shape[0]) * 5.0
            np.testing.assert_allclose(pts, route_points(route, u), atol=1e-9)
            np.testing.assert_allclose(env.body(10), pts, atol=1e-9)
            np.testing.assert_allclose(env.tip, route.tip(), atol=1e-9)
    assert stages == 5


def test_shift_and_copy_and_retraction():
    env = gym.make(ENV_ID, start_height=0.0).unwrapped
    env.reset(seed=0, options={"target": (100.0, 30.0, 60.0)})
    for _ in range(9):
        env.step(np.array([0.0, 0.0, 1.0], dtype=np.float32))
    env.step(np.array([1.0, 0.0, 1.0], dtype=np.float32))  # steer, then cross the stage
    assert env.insertion == 50.0
    np.testing.assert_allclose(env.route_kappa, [[0.1, 0.0], [0.1, 0.0]])  # frozen, then copied
    env.step(np.array([0.0, 1.0, -1.0], dtype=np.float32))  # steer the new one, pull back
    np.testing.assert_allclose(env.route_kappa, [[0.1, 0.0]])  # retracted along the route
    assert env.insertion == 45.0


def test_targets_per_bay_and_by_option():
    for bay, sign in ((1, -1), (2, 1)):
        env = gym.make(ENV_ID, bay=bay)
        for seed in range(10):
            _, info = env.reset(seed=seed)
            t = info["target"]
            assert sign * (t[1] - 60.0) > 2.0
            assert point_clearance(env.unwrapped.tank, t[None])[0] >= 10.0
    # target_clearance moves the draws' bound, nearer the surfaces and the corners
    env = gym.make(ENV_ID, bay=2, target_clearance=5.0)
    near = np.array([env.reset(seed=seed)[1]["target"] for seed in range(40)])
    clear = point_clearance(env.unwrapped.tank, near)
    assert (clear >= 5.0).all() and (clear < 10.0).any()
    env = gym.make(ENV_ID)
    obs, info = env.reset(options={"target": (230, 140, 90)})
    np.testing.assert_allclose(obs["desired_goal"], [230, 140, 90])


def test_detour_bias_draws_more_targets_behind_obstacles():
    """detour_bias weights targets by 1 + their raster detour; 0 leaves the draws unchanged."""
    from aftir_rl.rl.sb3.evaluation import evaluation_targets

    def targets(**kwargs):
        env = ArmFTLEnv(bay=2, **kwargs)
        return np.array([env.reset(seed=i)[1]["target"] for i in range(300)]), env

    plain, env = targets()
    np.testing.assert_array_equal(plain, targets(detour_bias=0.0)[0])
    biased, _ = targets(detour_bias=1.0)
    again, _ = targets(detour_bias=1.0)
    np.testing.assert_array_equal(biased, again)  # seeded
    raster = env.tank.raster
    row = raster_detour_table(env.tank)[raster.cell_indices(env.sampler.start_tip)]
    detour = {name: row[raster.cell_indices(t)] for name, t in (("u", plain), ("b", biased))}
    # the expected detour under density ∝ (1 + e), from the uniform draws: E[e(1+e)] / E[1+e]
    expected = (detour["u"] * (1 + detour["u"])).mean() / (1 + detour["u"]).mean()
    assert detour["b"].mean() == pytest.approx(expected, rel=0.15)
    assert detour["b"].mean() > 1.3 * detour["u"].mean()
    assert (point_clearance(env.tank, biased) >= 10.0).all()
    # evaluations draw uniformly whatever the training bias
    np.testing.assert_array_equal(
        evaluation_targets(ENV_ID, 5, env_kwargs={"bay": 2, "detour_bias": 1.0}),
        evaluation_targets(ENV_ID, 5, env_kwargs={"bay": 2}),
    )
    # and at the default 10 cm from the surfaces, whatever clearance training drew them with
    near = evaluation_targets(ENV_ID, 5, env_kwargs={"bay": 2, "target_clearance": 5.0})
    np.testing.assert_array_equal(near, evaluation_targets(ENV_ID, 5, env_kwargs={"bay": 2}))
    assert (point_clearance(env.tank, np.array(near)) >= 10.0).all()
    vec = gym.make_vec(
        ENV_ID, num_envs=4, vectorization_mode="vector_entry_point", bay=2, detour_bias=0.5
    )
    obs, _ = vec.reset(seed=11)
    singles = [ArmFTLEnv(bay=2, detour_bias=0.5).reset(seed=11 + i)[1]["target"] for i in range(4)]
    np.testing.assert_allclose(obs["desired_goal"], np.array(singles, dtype=np.float32))


def test_corner_bias_draws_targets_in_the_regions_corners():
    """corner_bias draws that fraction in the eight corner cubes; 0 leaves the draws unchanged."""
    from aftir_rl.envs.ftl.targets import CORNER_DEPTH, bay_region
    from aftir_rl.rl.sb3.evaluation import evaluation_targets

    def targets(n=200, **kwargs):
        env = ArmFTLEnv(bay=2, **kwargs)
        return np.array([env.reset(seed=i)[1]["target"] for i in range(n)]), env

    def in_corner(t, lo, hi, clearance):
        depth = np.minimum(t - lo, hi - t)  # per axis, from the nearer face
        return ((depth >= clearance - 1e-9) & (depth <= clearance + CORNER_DEPTH)).all(-1)

    plain, env = targets()
    np.testing.assert_array_equal(plain, targets(corner_bias=0.0)[0])
    lo, hi = bay_region(env.tank, 2)
    every, _ = targets(corner_bias=1.0)
    np.testing.assert_array_equal(every, targets(corner_bias=1.0)[0])  # seeded
    assert in_corner(every, lo, hi, 10.0).all()
    assert (point_clearance(env.tank, every) >= 10.0).all()
    # each of the eight corners comes up (the side of every axis is drawn)
    sides = {tuple(row) for row in (every > (lo + hi) / 2).astype(int)}
    assert len(sides) == 8
    near, _ = targets(corner_bias=1.0, target_clearance=6.0)
    assert in_corner(near, lo, hi, 6.0).all() and (point_clearance(env.tank, near) >= 6.0).all()
    half, _ = targets(400, corner_bias=0.5)
    share = in_corner(half, lo, hi, 10.0).mean()
    assert 0.4 < share < 0.6  # uniform draws land in the corner cubes about 1% of the time
    assert in_corner(plain, lo, hi, 10.0).mean() < 0.05
    # evaluations draw uniformly whatever the training bias
    np.testing.assert_array_equal(
        evaluation_targets(ENV_ID, 5, env_kwargs={"bay": 2, "corner_bias": 1.0}),
        evaluation_targets(ENV_ID, 5, env_kwargs={"bay": 2}),
    )
    with pytest.raises(ConfigError):
        ArmFTLEnv(bay=2, corner_bias=0.5, detour_bias=0.5)


def test_slack_tightens_training_and_evaluations_drop_it():
    """slack: success within tolerance − slack, contact below margin + slack; training-only."""
    from aftir_rl.rl.sb3.evaluation import evaluation_env_kwargs, evaluation_targets

    plain, strict = ArmFTLEnv(bay=2), ArmFTLEnv(bay=2, slack=0.5)
    assert (strict.batch.success_tolerance, strict.batch.margin) == (1.5, 1.5)
    assert (plain.batch.success_tolerance, plain.batch.margin) == (2.0, 1.0)
    target = np.array([[300.0, 100.0, 60.0]])
    info = {"prev_achieved_goal": target + [[0.0, 0.0, 3.0]], "contact": False}
    for d, both in ((1.8, False), (1.2, True)):
        tip = target + [[0.0, 0.0, d]]
        # the success bonus is paid on the plain rule at 1.8 cm, on the strict one only at 1.2
        assert plain.compute_reward(tip, target, info)[0] > 5
        assert (strict.compute_reward(tip, target, info)[0] > 5) == both
    # pushed straight up in 0.5 cm steps, the same arm ends on contact at 1.5 cm with slack
    ends = []
    for env in (plain, strict):
        env.reset(seed=4)
        for _ in range(2000):
            _, _, terminated, _, info = env.step(np.array([0.0, 0.0, 0.1], dtype=np.float32))
            if terminated:
                break
        assert info["contact"] and not info["is_success"]
        ends.append((info["min_clearance_cm"], env.batch.dis[0]))
    (clear_plain, dis_plain), (clear_strict, dis_strict) = ends
    assert 0.5 <= clear_plain < 1.0 <= clear_strict < 1.5 and dis_strict < dis_plain
    np.testing.assert_array_equal(
        plain.reset(seed=9)[1]["target"], strict.reset(seed=9)[1]["target"]
    )
    # evaluations build the env without it (and without the other training-only kwargs)
    kwargs = {"bay": 2, "guide": True, "slack": 0.5, "corner_bias": 0.25, "target_clearance": 6}
    assert evaluation_env_kwargs({**kwargs, "failure_bias": 0.5}) == {"bay": 2, "guide": True}
    np.testing.assert_array_equal(
        evaluation_targets(ENV_ID, 5, env_kwargs={"bay": 2, "slack": 0.5}),
        evaluation_targets(ENV_ID, 5, env_kwargs={"bay": 2}),
    )


def test_failure_bias_draws_targets_where_episodes_fail():
    """failure_bias: targets come up in proportion to their cell's failure rate."""
    rows = 512
    biased, plain = (
        gym.make_vec(
            ENV_ID, num_envs=rows, vectorization_mode="vector_entry_point", bay=2, **kwargs
        ).unwrapped
        for kwargs in ({"failure_bias": 1.0, "corner_bias": 0.25}, {"corner_bias": 0.25})
    )
    raster = biased.tank.raster
    # every cell solved except the cell of a random target, failed every time
    _, info = plain.reset(seed=50)
    hard = raster.cell_indices(info["target"])[7]
    cells = np.arange(raster.n_cells)
    rates = biased.sampler.failures
    for _ in range(400):
        rates.record(cells, cells != hard)
    assert rates.count == 400 * len(cells)
    np.testing.assert_allclose(rates.weight(cells), np.where(cells == hard, 1.0, rates.floor))
    counts = []
    for env in (biased, plain):
        _, info = env.reset(seed=60)
        counts.append(int((raster.cell_indices(info["target"]) == hard).sum()))
    # about rows/len(cells) uniformly (a few), about rows/(1 + 0.05 (cells − 1)) biased
    assert counts[0] >= 4 * max(counts[1], 3), counts


@pytest.mark.parametrize("vector", [False, True])
def test_failure_bias_records_every_ended_episode(vector):
    rng = np.random.default_rng(8)
    actions = rng.uniform(-1, 1, (120, 4, 3)).astype(np.float32)
    actions[..., 2] = np.abs(actions[..., 2])
    if vector:
        env = gym.make_vec(
            ENV_ID,
            num_envs=4,
            vectorization_mode="vector_entry_point",
            max_episode_steps=25,
            failure_bias=0.5,
            autoreset_mode="SameStep",
        )
        env.reset(seed=1)
        ended = successes = 0
        for a in actions:
            _, _, term, trunc, info = env.step(a)
            ended += int((term | trunc).sum())
            successes += int(info["is_success"].sum())
    else:
        env = gym.make(ENV_ID, max_episode_steps=25, failure_bias=0.5)
        steps = rollout(env, actions[:, 0], seed=1)
        ended = sum(s[4] or s[5] for s in steps)
        successes = sum(s[6]["is_success"] for s in steps)
        env.reset()  # the episode under way when the rollout stopped ends without success
        ended += not (steps[-1][4] or steps[-1][5])
    rates = env.unwrapped.sampler.failures
    assert ended > 4 and rates.count == ended and rates.seen.sum() >= 2
    # the rates moved down from 1 only by successes
    assert (rates.fail < 1).sum() <= successes


@pytest.mark.parametrize(
    "kwargs, error",
    [
        ({"bay": 3}, ConfigError),
        ({"push_step": 80.0}, ConfigError),
        ({"n_sections": 0}, ConfigError),
        ({"detour_bias": 1.5}, ConfigError),
        ({"detour_bias": -0.1}, ConfigError),
        ({"corner_bias": 1.5}, ConfigError),
        ({"corner_bias": True}, ConfigError),
        ({"slack": -0.1}, ConfigError),
        ({"slack": 2.0}, ConfigError),
        ({"slack": True}, ConfigError),
        ({"failure_bias": 1.5}, ConfigError),
        ({"failure_bias": -0.1}, ConfigError),
        ({"failure_bias": True}, ConfigError),
        ({"failure_bias": 0.5, "detour_bias": 0.5}, ConfigError),
        ({"target": (0, 60, 50)}, TargetError),
        ({"target": (500, 0, 10)}, TargetError),
    ],
)
def test_bad_arguments(kwargs, error):
    with pytest.raises(error):
        gym.make(ENV_ID, **kwargs)


def test_bad_actions_and_options():
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    for bad in (np.zeros(2), np.array([np.nan, 0, 0]), "up"):
        with pytest.raises(InvalidActionError):
            env.step(bad)
    with pytest.raises(ConfigError, match="reset option"):
        env.reset(options={"goal": (0, 0, 50)})


def test_tank_distance_is_point_clearance(tank):
    rng = np.random.default_rng(0)
    p = rng.uniform(np.array(tank.box_min) - 40, np.array(tank.box_max) + 20, (20000, 3))
    np.testing.assert_allclose(TankDistance(tank)(p), point_clearance(tank, p), atol=1e-9)


@pytest.mark.parametrize(
    "shaping, guide, near_goal",
    [(False, False, False), ("field", False, False), ("field", True, False), (False, True, True)],
)
def test_vector_env_matches_single_envs(shaping, guide, near_goal):
    b, steps = 4, 120
    rng = np.random.default_rng(5)
    actions = rng.uniform(-1, 1, (steps, b, 3)).astype(np.float32)
    actions[..., 2] = np.abs(actions[..., 2])
    venv = gym.make_vec(
        ENV_ID,
        num_envs=b,
        vectorization_mode="vector_entry_point",
        max_episode_steps=40,
        shaping=shaping,
        guide=guide,
        near_goal=near_goal,
    )
    obs, _ = venv.reset(seed=10)
    v_rows = []
    for t in range(steps):
        nxt, r, term, trunc, info = venv.step(actions[t])
        v_rows.append((obs, r, term, trunc, nxt))
        obs = nxt
    for i in range(b):
        env = gym.make(
            ENV_ID, max_episode_steps=40, shaping=shaping, guide=guide, near_goal=near_goal
        )
        o, _ = env.reset(seed=10 + i)
        done = False
        for t in range(steps):
            v_obs, v_r, v_term, v_trunc, v_next = v_rows[t]
            if done:  # next-step autoreset: the vector env resets this row now
                o, _ = env.reset()
                assert v_r[i] == 0 and not v_term[i] and not v_trunc[i]
                for key in o:
                    np.testing.assert_array_equal(v_next[key][i], o[key])
                done = False
                continue
            for key in o:
                np.testing.assert_array_equal(v_obs[key][i], o[key])
            o, r, term, trunc, _ = env.step(actions[t, i])
            assert (r, term, trunc) == (v_r[i], v_term[i], v_trunc[i])
            done = term or trunc


def test_reward_reuses_the_observations_guide_queries(monkeypatch):
    """With the guide observed, the reward asks the guide nothing the observations asked."""
    from aftir_rl.envs.ftl.fields import FieldGuide

    venv = gym.make_vec(
        ENV_ID,
        num_envs=8,
        vectorization_mode="vector_entry_point",
        shaping="field",
        guide=True,
        max_episode_steps=3,
        autoreset_mode="SameStep",
    )
    calls = []
    query = FieldGuide.__call__
    monkeypatch.setattr(FieldGuide, "__call__", lambda *a: calls.append(1) or query(*a))
    venv.reset(seed=3)
    batch = venv.unwrapped.batch
    # targets are kept as the float32 goals the reward is given
    np.testing.assert_array_equal(batch.target, batch.target.astype(np.float32))
    action = np.tile([0.3, -0.2, 0.5], (8, 1)).astype(np.float32)
    per_step = []
    for _ in range(7):
        calls.clear()
        _, _, term, trunc, _ = venv.step(action)
        per_step.append((len(calls), bool((term | trunc).all())))
    # one query a step for every row's observation, one more in a step whose rows restart (their
    # first observations); the potentials at the start (after a reset or a restart) come free
    assert per_step == [(1, False), (1, False), (2, True)] * 2 + [(1, False)]
    tips, targets, to_go = batch.guide_queries[-1]
    fresh, _ = query(batch.guide, tips, targets, batch.guide.field_ids(targets))
    np.testing.assert_array_equal(to_go, fresh)


def test_vector_env_targets_option():
    venv = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point")
    obs, _ = venv.reset(seed=0, options={"target": (230, 140, 90)})
    np.testing.assert_allclose(obs["desired_goal"], [[230, 140, 90]] * 3)
    with pytest.raises(TargetError):
        venv.reset(options={"target": np.zeros((2, 3))})


def test_sac_her_smoke():
    from stable_baselines3 import SAC, HerReplayBuffer

    env = gym.make(ENV_ID, shaping=True, max_episode_steps=30)
    sac = SAC(
        "MultiInputPolicy",
        env,
        learning_starts=60,
        batch_size=16,
        buffer_size=1000,
        policy_kwargs={"net_arch": [16]},
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"copy_info_dict": True, "n_sampled_goal": 2},
        train_freq=4,
        seed=0,
    )
    sac.learn(152)  # train_freq 4
    assert sac.num_timesteps == 152


def test_ppo_smoke():
    from stable_baselines3 import PPO

    env = gym.make(ENV_ID, shaping=True, max_episode_steps=30)
    ppo = PPO(
        "MultiInputPolicy",
        env,
        n_steps=64,
        batch_size=32,
        n_epochs=1,
        policy_kwargs={"net_arch": [16]},
        seed=0,
    )
    ppo.learn(128)
    assert ppo.num_timesteps == 128
    action, _ = ppo.predict(env.reset(seed=0)[0], deterministic=True)
    assert env.action_space.contains(action)


def test_render_rgb_array():
    env = gym.make(ENV_ID, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.array([0.5, 0.0, 1.0], dtype=np.float32))
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3


def test_arm_env_api_used_by_the_evaluator():
    env: ArmFTLEnv = gym.make(ENV_ID).unwrapped
    env.reset(seed=0)
    assert env.tip.shape == (3,) and env.body().shape == (12 * 10 + 1, 3)
    assert env.posture.n_sections == 12
    np.testing.assert_allclose(env.posture.tip(50.0), env.tip, atol=1e-9)


@pytest.mark.slow
def test_train_cli_sac_her(tmp_path):
    import yaml

    from aftir_rl.cli.train import main

    config = {"env_id": "AFTIR-ArmFTL-v0", "total_timesteps": 400, "eval_freq": 400}
    config.update(eval_targets=2, checkpoint_freq=400)  # HER from the entry of sac.yml
    config["hyperparameters"] = dict(
        learning_starts=320, batch_size=16, buffer_size=2000, policy_kwargs={"net_arch": [16]}
    )
    path = tmp_path / "sac.yaml"
    path.write_text(yaml.safe_dump(config))
    assert main(["sac", "--config", str(path), "--logdir", str(tmp_path), "--no-progress"]) == 0
    runs = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert len(runs) == 1 and (runs[0] / "model.zip").is_file()
    csv = (runs[0] / "progress.csv").read_text()
    assert "eval/success_rate" in csv and "eval/tip_error_cm" in csv


def test_spec_checks_hold_however_it_is_built():
    from aftir_rl.envs.ftl.spec import FTLSpec, TaskSpec, TrainingSpec

    with pytest.raises(ConfigError, match="slack"):
        FTLSpec(task=TaskSpec(success_tolerance=2.0), training=TrainingSpec(slack=4.0))
    with pytest.raises(ConfigError, match="unexpected keyword argument 'colour'"):
        FTLSpec.from_kwargs(colour="red")
    with pytest.raises(TypeError, match="unexpected keyword argument 'shapping'"):
        gym.make(ENV_ID, shapping=True)  # as Python says it: wrappers that drop it go on
