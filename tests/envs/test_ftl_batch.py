"""AFTIR-ArmFTL-v0's batched kernels: exact grid-pruned clearances, raster guide, SB3 adapter."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

from aftir_rl.core.collision import CollisionScene, point_clearance
from aftir_rl.core.kernel.clearance import clearance_grid
from aftir_rl.core.robot import Posture, body_points, forward_kinematics
from aftir_rl.core.tank import load_tank
from aftir_rl.envs.ftl.env import ArmFTLEnv, ArmFTLVectorEnv
from aftir_rl.envs.ftl.fields import field_guide, raster_distance_table
from aftir_rl.envs.ftl.targets import draw_targets
from aftir_rl.planning.ftl.model import kappa_to_angles
from tests.helpers import random_ftl_batch

ENV_ID = "AFTIR-ArmFTL-v0"


def random_arms(tank, rng, b):
    """Backbone samples of ``b`` random 12-section postures, deployed 0..600 cm."""
    theta = rng.uniform(0, tank.arm.theta_max, (b, 12))
    phi = rng.uniform(-np.pi, np.pi, (b, 12))
    dis = rng.uniform(-600, 0, b)
    return body_points(dis, theta, phi, tank.arm.section_length, 10)


@pytest.mark.parametrize("name", ["b737_center", "single_cabin", "open_space_obstacles1"])
def test_grid_row_min_is_the_exact_minimum(name):
    tank = load_tank(name)
    rng = np.random.default_rng(1)
    pts = random_arms(tank, rng, 2000)
    grid = clearance_grid(tank)
    exact = point_clearance(tank, pts.reshape(-1, 3)).reshape(pts.shape[:2])
    np.testing.assert_allclose(grid.row_min(pts), exact.min(1), atol=1e-9)
    use = rng.random(pts.shape[:2]) < 0.5
    use[:, 0] = True
    np.testing.assert_allclose(
        grid.row_min(pts, use), np.where(use, exact, np.inf).min(1), atol=1e-9
    )
    approx = grid.approx(pts[:200])
    assert np.abs(approx - exact[:200]).max() <= grid.slack + 1e-9


def test_body_clearance_below_the_floor_uses_the_base():
    """Samples deep in the guide are skipped; the env's clearance is still the exact minimum."""
    env = ArmFTLEnv()
    rng = np.random.default_rng(3)
    env.reset(seed=0)
    for _ in range(60):
        env.step(np.array([*rng.uniform(-1, 1, 2), 1.0], dtype=np.float32))
        exact = point_clearance(env.tank, env.batch.points[0]).min() - env.tank.arm.radius
        assert env.batch.body_clearance[0] == pytest.approx(exact, abs=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "count"),
    [("b737_center", 10_000), ("single_cabin", 3000), ("open_space_obstacles1", 3000)],
)
def test_contact_verdicts_against_python_fcl(name, count):
    """The batched env's contact verdicts on random FTL postures, against python-fcl's capsules.

    The env reads the whole backbone (its samples ``l/10`` apart, and between them); python-fcl,
    capsules on the chords between the same samples, each within a link's sagitta of the arc. So
    the verdicts may differ only where python-fcl's clearance lies within the sagitta (and
    rounding) of the margin; and the samples' clearance is never more than
    :meth:`CollisionScene.sample_margin` (half the spacing, the sagitta and 0.1 cm: 2.7 cm for
    50 cm sections) above python-fcl's.
    """
    tank = load_tank(name)
    rng = np.random.default_rng(7)
    margin = 1.0
    batch = random_ftl_batch(tank, rng, count, margin)
    batch.refresh()
    scene = CollisionScene(tank, links_per_section=10)
    fcl_clear = np.array(
        [scene.clearance(Posture(batch.dis[i], batch.theta[i], batch.phi[i])) for i in range(count)]
    )
    band = scene.sample_margin(10)
    bend, link = tank.arm.theta_max / 10, tank.arm.section_length / 10
    sagitta = link / bend * (1 - np.cos(bend / 2))
    # both kinds of posture are there, and many near the margin
    assert 0.1 < batch.contact.mean() < 0.95
    assert (np.abs(fcl_clear - margin) < 10.0).sum() >= 50
    free = fcl_clear > 0
    assert (batch.body_clearance[free] - fcl_clear[free]).max() <= band
    assert (batch.surface_clearance <= batch.body_clearance).all()
    differ = batch.contact != (fcl_clear < margin)
    assert (np.abs(fcl_clear[differ] - margin) <= sagitta + 0.01).all()


def test_raster_distance_table_against_bfs():
    tank = load_tank("b737_center")
    table = raster_distance_table(tank)
    raster = tank.raster
    free = np.flatnonzero(~raster.obstructed.reshape(-1))
    for start in free[:: max(1, len(free) // 7)]:
        cell = np.unravel_index(start, raster.shape)
        bfs = raster.bfs_distances(tuple(int(c) for c in cell)).reshape(-1)
        reach = (bfs >= 0) & ~raster.obstructed.reshape(-1)
        np.testing.assert_array_equal(table[start][reach], bfs[reach])


def test_raster_distance_table_ends_and_sources_inside_solids():
    """Every entry of sampled rows, obstructed cells included, against an independent BFS.

    The documented rule: the path's cells before its end are free; an obstructed end is one step
    from a reached free neighbour (or from the source); an obstructed source counts from either
    end (the same steps either way: free paths reverse). A generated 3-bay wing: baffles,
    stringers and holes give many partly filled cells.
    """
    from collections import deque

    tank = load_tank("wing:3:11")
    table = raster_distance_table(tank)
    raster = tank.raster
    obstructed = raster.obstructed
    shape = raster.shape

    def neighbours(cell):
        for axis in range(3):
            for step in (-1, 1):
                n = list(cell)
                n[axis] += step
                if 0 <= n[axis] < shape[axis]:
                    yield tuple(n)

    def row(src):  # steps from src: free cells by BFS, then obstructed ends, -1 where none
        dist = np.full(shape, -1)
        dist[src] = 0
        queue = deque([src])
        while queue:
            cur = queue.popleft()
            for n in neighbours(cur):
                if not obstructed[n] and dist[n] < 0:
                    dist[n] = dist[cur] + 1
                    queue.append(n)
        ends = dist.copy()
        for cell in map(tuple, np.argwhere(obstructed)):
            if cell != src:
                near = [dist[n] for n in neighbours(cell) if dist[n] >= 0]
                ends[cell] = min(near) + 1 if near else -1
        return ends.reshape(-1)

    rng = np.random.default_rng(5)
    cells = np.argwhere(np.ones(shape, bool))
    sources = [tuple(c) for c in np.argwhere(obstructed)[rng.choice(obstructed.sum(), 4)]]
    sources += [tuple(c) for c in np.argwhere(~obstructed)[rng.choice((~obstructed).sum(), 4)]]
    assert any(obstructed[src] for src in sources) and len(cells) == raster.n_cells
    finite_max = table[table < table.max()].max() if (table < table.max()).any() else 0
    for src in sources:
        i, mine = raster.index(src), row(src)
        reached = mine >= 0
        np.testing.assert_array_equal(table[i][reached], mine[reached])
        assert np.all(table[i][~reached] > finite_max - 1)  # unreachable: past every distance
    index = [raster.index(src) for src in sources]
    np.testing.assert_array_equal(table[np.ix_(index, index)], table[np.ix_(index, index)].T)


def test_guide_leads_through_the_hatch():
    """Following the guide's way from bay 1 reaches a bay-2 target, and P is GuideField's."""
    from aftir_rl.planning.ftl.route import GuideField

    tank = load_tank("b737_center")
    guide = field_guide(tank)
    rng = np.random.default_rng(0)
    env = ArmFTLEnv(bay=2)
    targets = draw_targets([rng], env.tank, env.sampler.region, 10.0, env.sampler.start_tip)
    targets = np.concatenate([targets, [[200.0, 120.0, 50.0]]])
    starts = np.array([[100.0, 20.0, 20.0], [0.0, 0.0, 10.0]])
    for target in targets:
        ids = guide.field_ids(np.repeat(target[None], len(starts), 0))
        centre = guide.origin + (np.floor((target - guide.origin) / guide.size) + 0.5) * guide.size
        p = starts.copy()
        # P is the distance-to-go of the GuideField of the target's cell centre
        np.testing.assert_allclose(
            guide(p, np.repeat(target[None], len(p), 0), ids)[0],
            GuideField(tank, centre, None, guide.clearance_cost)(p),
            rtol=1e-6,
        )
        for _ in range(150):
            _, way = guide(p, np.repeat(target[None], len(p), 0), ids)
            p = p + 2.0 * way
        assert np.linalg.norm(p - target, axis=1).max() < 3.0
    # the path never passed through the baffle elsewhere than its hatch: checked by the
    # distances staying positive along one walk
    p = starts[:1].copy()
    ids = guide.field_ids(targets[-1:])
    for _ in range(150):
        assert point_clearance(tank, p)[0] > 0
        p = p + 2.0 * guide(p, targets[-1:], ids)[1]


def test_lookahead_follows_the_shortest_way():
    """Each hop goes to the neighbour that satisfies the field's Bellman equation, the way
    reaches the target (ending on it), and clearance as a cost keeps the way off the hatch's
    edges where the plain field hugs them."""
    from aftir_rl.planning.ftl.route import GuideField

    tank = load_tank("b737_center")
    guide = field_guide(tank)
    target = np.array([[-40.0, 120.0, 30.0]])  # behind the baffle, far from the hatch
    (row,) = guide.field_ids(target)
    dist = guide._table[row].astype(np.float64)
    field = GuideField(tank, target[0], None, guide.clearance_cost)
    shape = tuple(guide.shape)
    rng = np.random.default_rng(0)
    cells = rng.choice(np.flatnonzero(np.isfinite(dist)), 300, replace=False)
    for c in cells:
        n = guide._next[row, c]
        if n == c:  # only the target's own points stay
            assert dist[c] <= 1.75 * guide.size
            continue
        d = np.subtract(np.unravel_index(n, shape), np.unravel_index(c, shape))
        (e,) = np.flatnonzero((guide.neighbours == d).all(1))
        assert guide.edges[e][np.unravel_index(c, shape)]
        w = field.weights[e]
        w = w[np.unravel_index(c, shape)] if np.ndim(w) else w
        assert dist[n] + w == pytest.approx(dist[c], rel=1e-5)
    # from the start, hop by hop: the points lead through the hatch to the target itself
    p = np.array([[0.0, 0.0, 10.0]])
    crossings = []
    for _ in range(60):
        nxt = guide.lookahead(p, target, np.array([row]), (1,))[:, 0]
        if (p[0, 1] - 60) * (nxt[0, 1] - 60) <= 0 and p[0, 1] != nxt[0, 1]:
            crossings.append((p[0] + nxt[0]) / 2)
        p = nxt
    np.testing.assert_array_equal(p, target)
    assert len(crossings) == 1 and 80 < crossings[0][0] < 120 and 30 < crossings[0][2] < 70
    # the costed way crosses the hatch away from its edges (the plain one: at x = 85)
    assert crossings[0][0] > 90
    # both fields, plain and costed, are the shortest ways: Dijkstra over the same edges agrees
    for f in (GuideField(tank, target[0]), field):
        np.testing.assert_allclose(f.dist, dijkstra(f), rtol=1e-9)


def dijkstra(field):
    """Shortest distances to the field's seeds by Dijkstra (heapq) over its edges and weights."""
    import heapq

    from aftir_rl.planning.ftl.guide import NEIGHBOURS

    shape = tuple(int(v) for v in field.shape)
    dist = np.full(shape, np.inf)
    seeds = np.isfinite(field.dist) & (field.dist <= 1.75 * field.size)
    heap = [(float(field.dist[c]), c) for c in map(tuple, np.argwhere(seeds))]
    for d0, c in heap:
        dist[c] = d0
    heapq.heapify(heap)
    while heap:
        d0, y = heapq.heappop(heap)
        if d0 > dist[y]:
            continue
        for e, d in enumerate(NEIGHBOURS):  # x -> y = x + d
            x = tuple(np.subtract(y, d))
            if not all(0 <= x[i] < shape[i] for i in range(3)):
                continue
            if not (field.edges[e][x] and field.free[x]):
                continue
            w = field.weights[e]
            nd = d0 + float(w[x] if np.ndim(w) else w)
            if nd < dist[x]:
                dist[x] = nd
                heapq.heappush(heap, (nd, x))
    return dist


def test_draw_targets_are_free_and_reproducible():
    env = ArmFTLEnv(bay=2)
    rngs = [np.random.default_rng(i) for i in range(50)]
    t = draw_targets(rngs, env.tank, env.sampler.region, 10.0, env.sampler.start_tip)
    assert (point_clearance(env.tank, t) >= 10.0).all()
    assert (t[:, env.tank.baffle.index] > env.tank.baffle.position).all()
    again = draw_targets(
        [np.random.default_rng(i) for i in range(50)],
        env.tank,
        env.sampler.region,
        10.0,
        env.sampler.start_tip,
    )
    np.testing.assert_array_equal(t, again)


@pytest.mark.parametrize("corners", [0.0, 0.5])
def test_draw_targets_are_the_first_free_candidates(corners):
    """Each target is its generator's first candidate free by the exact distance (a numpy loop)."""
    from aftir_rl.envs.ftl.targets import corner_candidates

    env = ArmFTLEnv(bay=2)
    lo, hi = env.sampler.region

    def reference(rng, clearance):
        corner = corners > 0 and rng.random() < corners
        for _ in range(200):
            cand = (
                corner_candidates(rng, lo, hi, clearance)
                if corner
                else rng.uniform(lo, hi, (64, 3))
            )
            ok = point_clearance(env.tank, cand) >= clearance
            ok &= np.linalg.norm(cand - env.sampler.start_tip, axis=1) >= 20.0
            if ok.any():
                return cand[ok.argmax()]
        raise AssertionError("no target")

    for clearance in (6.0, 10.0):
        drawn = draw_targets(
            [np.random.default_rng(i) for i in range(60)],
            env.tank,
            env.sampler.region,
            clearance,
            env.sampler.start_tip,
            corners=corners,
        )
        expected = [reference(np.random.default_rng(i), clearance) for i in range(60)]
        np.testing.assert_array_equal(drawn, expected)


def route_frame(kappa, k, l):
    """Rotation of the route's frame after its first ``k`` sections, by forward kinematics."""
    theta, phi = kappa_to_angles(kappa[:k])
    return forward_kinematics(0.0, theta, phi, l)[-1, :3, :3]


def test_guide_observation():
    env = gym.make(ENV_ID, guide=True)
    plain = gym.make(ENV_ID)
    obs, _ = env.reset(seed=0)
    assert obs["observation"].shape[0] == plain.observation_space["observation"].shape[0] + 16
    # straight arm: the steering frame is the world's
    tail = obs["observation"][-12:-9]
    np.testing.assert_allclose(tail, (obs["desired_goal"] - obs["achieved_goal"]) / 100, atol=1e-5)
    np.testing.assert_allclose(obs["observation"][-9:-6], [0, 0, 1], atol=1e-6)
    # ... and the lookahead's unit directions are the world's
    batch = env.unwrapped.batch
    ahead = batch.guide.lookahead(batch.tip, batch.target, batch.target_fields())[0] - batch.tip[0]
    ahead /= np.linalg.norm(ahead, axis=1, keepdims=True)
    np.testing.assert_allclose(obs["observation"][-6:], ahead.reshape(-1), atol=1e-6)
    # after a bend and a push past a section end, the frame is the frozen section's end frame
    rng = np.random.default_rng(0)
    for _ in range(14):
        obs, *_ = env.step(np.array([*rng.uniform(-1, 1, 2), 1.0], dtype=np.float32))
    assert batch.k[0] >= 1
    frame = route_frame(batch.kappa[0], batch.k[0], batch.l)
    np.testing.assert_allclose(batch.steering_frames()[0], frame, atol=1e-9)
    from gymnasium.utils.env_checker import check_env

    check_env(env.unwrapped, skip_render_check=True)


def test_near_goal_observation():
    """The near-goal columns: the target's offset over max(d, 10 cm), in the steering frame."""
    from aftir_rl.envs.ftl.state import NEAR_GOAL_RANGE

    env = gym.make(ENV_ID, guide=True, near_goal=True)
    plain = gym.make(ENV_ID, guide=True)
    obs, _ = env.reset(seed=0)
    assert obs["observation"].shape[0] == plain.observation_space["observation"].shape[0] + 3
    # the guide's columns keep their place, the near-goal ones come last
    plain_obs, _ = plain.reset(seed=0)
    np.testing.assert_array_equal(obs["observation"][:-3], plain_obs["observation"])
    batch = env.unwrapped.batch
    rng = np.random.default_rng(3)
    for _ in range(14):  # bend and push past a section end: a frame that is not the world's
        obs, *_ = env.step(np.array([*rng.uniform(-1, 1, 2), 1.0], dtype=np.float32))
    assert batch.k[0] >= 1
    frame = route_frame(batch.kappa[0], batch.k[0], batch.l)
    tip = batch.tip[0]
    for offset in ([3.0, -4.0, 1.0], [0.5, 0.0, 0.0], [30.0, 40.0, 0.0], [0.0, 0.0, 0.0]):
        batch.target[0] = tip + np.array(offset)
        d = np.linalg.norm(offset)
        expect = frame.T @ np.array(offset) / max(d, NEAR_GOAL_RANGE)
        np.testing.assert_allclose(batch.observation()[0, -3:], expect, atol=1e-6)
        assert np.linalg.norm(batch.near_goal_columns()[0]) == pytest.approx(
            min(d / NEAR_GOAL_RANGE, 1.0)
        )
    from aftir_rl.core.errors import ConfigError

    with pytest.raises(ConfigError, match="near_goal"):
        gym.make(ENV_ID, near_goal="yes")


@pytest.mark.parametrize("shaping", [False, "field"])
def test_same_step_autoreset_keeps_the_transitions(shaping):
    """SameStep rows see the transitions of NextStep rows, minus the extra reset step.

    With shaping, the rows reuse their previous step's potential; the single envs' rewards are
    checked against ``compute_reward`` in ``test_arm_ftl.py``.
    """
    b, steps = 3, 90
    rng = np.random.default_rng(2)
    actions = rng.uniform(-1, 1, (steps, b, 3)).astype(np.float32)
    actions[..., 2] = np.abs(actions[..., 2])
    same = ArmFTLVectorEnv(
        num_envs=b, max_episode_steps=25, autoreset_mode="SameStep", shaping=shaping
    )
    single = [ArmFTLEnv(shaping=shaping) for _ in range(b)]
    obs, _ = same.reset(seed=4)
    for i, env in enumerate(single):
        env.reset(seed=4 + i)
    for t in range(steps):
        nxt, r, term, trunc, info = same.step(actions[t])
        for i, env in enumerate(single):
            o, r1, te, _, _ = env.step(actions[t, i])
            assert r1 == r[i] and te == term[i]
            if term[i] or trunc[i]:
                for key in o:
                    np.testing.assert_array_equal(info["final_obs"][i][key], o[key])
                o, _ = env.reset()
            for key in o:
                np.testing.assert_array_equal(nxt[key][i], o[key])


def test_sb3_adapter_trains_ppo_and_sac_her():
    from stable_baselines3 import PPO, SAC, HerReplayBuffer
    from stable_baselines3.common.vec_env import VecEnv

    from aftir_rl.rl.sb3.vec_adapter import make_batched_vec_env

    venv = make_batched_vec_env(f"aftir_rl:{ENV_ID}", 8, 0, {"guide": True, "shaping": True})
    assert isinstance(venv, VecEnv)
    ppo = PPO(
        "MultiInputPolicy",
        venv,
        n_steps=16,
        batch_size=64,
        n_epochs=1,
        policy_kwargs={"net_arch": [16]},
        seed=0,
    )
    ppo.learn(256)
    assert ppo.num_timesteps == 256
    venv = make_batched_vec_env(f"aftir_rl:{ENV_ID}", 4, 0, {"max_episode_steps": 20})
    sac = SAC(
        "MultiInputPolicy",
        venv,
        learning_starts=80,
        batch_size=16,
        buffer_size=1000,
        policy_kwargs={"net_arch": [16]},
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"copy_info_dict": True, "n_sampled_goal": 2},
        train_freq=1,
        seed=0,
    )
    sac.learn(160)
    assert sac.num_timesteps == 160


@pytest.mark.parametrize("keys", [(), ("contact",)])
def test_sb3_adapter_running_info_keys(keys):
    """Rows that did not finish get only the keys asked for; everything else is the same."""
    from aftir_rl.rl.sb3.vec_adapter import make_batched_vec_env

    rng = np.random.default_rng(8)
    actions = rng.uniform(-1, 1, (60, 4, 3)).astype(np.float32)
    actions[..., 2] = np.abs(actions[..., 2])
    kwargs = {"max_episode_steps": 15, "shaping": "field"}
    full = make_batched_vec_env(f"aftir_rl:{ENV_ID}", 4, 3, kwargs)
    lean = make_batched_vec_env(f"aftir_rl:{ENV_ID}", 4, 3, kwargs, keys)
    first = lean.reset()
    for key, value in full.reset().items():
        np.testing.assert_array_equal(first[key], value)
    finished = 0
    for a in actions:
        o1, r1, d1, i1 = full.step(a)
        o2, r2, d2, i2 = lean.step(a)
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(d1, d2)
        for key in o1:
            np.testing.assert_array_equal(o1[key], o2[key])
        for row, (f, l) in enumerate(zip(i1, i2)):
            if d1[row]:
                finished += 1
                assert f.keys() == l.keys() and "episode" in l and "is_success" in l
                assert (l["episode"]["r"], l["episode"]["l"]) == (
                    f["episode"]["r"],
                    f["episode"]["l"],
                )
                for key in f.keys() - {"episode", "terminal_observation"}:
                    assert type(l[key]) is type(f[key]), key
                    np.testing.assert_array_equal(np.asarray(l[key]), np.asarray(f[key]))
                for key, value in f["terminal_observation"].items():
                    np.testing.assert_array_equal(l["terminal_observation"][key], value)
            else:
                assert set(l) == set(keys) and all(l[k] == f[k] for k in keys)
                assert len(f) > 1
    assert finished >= 4


def test_train_cli_ppo_on_the_batched_env(tmp_path):
    """configs/ppo_ftl.yaml, shrunk: 16 rows of the batched env, tags read back, model loads."""
    import yaml
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from aftir_rl.cli.train import main
    from aftir_rl.rl.sb3 import load_run

    config = yaml.safe_load(open("configs/ppo_ftl.yaml"))
    config.update(
        total_timesteps=512, n_envs=16, eval_freq=512, eval_targets=2, checkpoint_freq=512
    )
    config["hyperparameters"] = dict(  # over the entry of configs/hyperparams/ppo.yml
        n_steps=16, batch_size=128, n_epochs=1, policy_kwargs={"net_arch": [16]}
    )
    path = tmp_path / "ppo.yaml"
    path.write_text(yaml.safe_dump(config))
    assert main(["ppo", "--config", str(path), "--logdir", str(tmp_path), "--no-progress"]) == 0
    (run,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    events = EventAccumulator(str(run))
    events.Reload()
    tags = set(events.Tags()["scalars"])
    assert {"eval/success_rate", "eval/tip_error_cm", "eval/collision_rate"} <= tags
    assert "train/value_loss" in tags and "time/fps" in tags
    algo, loaded, _, model = load_run(run)  # rebuilt with the run's env_kwargs (the guide)
    assert algo == "ppo" and loaded.env_kwargs["guide"] is True
    guided = gym.make(ENV_ID, guide=True).observation_space["observation"]
    assert model.observation_space["observation"].shape == guided.shape
    # evaluate (and bench --model) make the env with the run's env_kwargs, so the shapes fit
    from aftir_rl.experiments.runs import evaluate_run

    row = evaluate_run(run, targets=[np.array([200.0, 120.0, 50.0])])
    assert row["targets"] == 1 and 0.0 <= row["success_rate"] <= 1.0
    # best/: the best evaluated model, a run directory of its own
    best = run / "best"
    assert (best / "config.json").read_bytes() == (run / "config.json").read_bytes()
    kept = json.loads((best / "best.json").read_text())
    rates = [e.value for e in events.Scalars("eval/success_rate")]
    assert len(rates) == 2 and kept["success_rate"] == pytest.approx(max(rates))
    assert 0 < kept["timesteps"] <= json.loads((run / "summary.json").read_text())["timesteps"]
    assert load_run(best)[0] == "ppo"
    # evaluate --random N --seed S: the env's own draws with those seeds
    from aftir_rl.cli.evaluate import main as evaluate_main
    from aftir_rl.rl.sb3 import evaluation_targets

    drawn = evaluate_run(best, draw=(3, 777))
    assert drawn["targets"] == 3
    again = evaluate_run(best, targets=evaluation_targets(ENV_ID, 3, 777, loaded.env_kwargs))
    assert again["tip_error_cm"] == pytest.approx(drawn["tip_error_cm"])
    logs = str(tmp_path / "logs")
    assert evaluate_main([str(best), "--random", "2", "--seed", "5", "--logdir", logs]) == 0
    assert evaluate_main([str(best), "--random", "0", "--logdir", logs]) == 2
    assert evaluate_main([str(best), "--seed", "5", "--logdir", logs]) == 2
    both = [str(best), "--random", "2", "--target", "200", "120", "50", "--logdir", logs]
    assert evaluate_main(both) == 2


def test_config_limits_for_the_batched_env():
    from aftir_rl.core.errors import ConfigError
    from aftir_rl.rl.sb3.config import SB3Config, check_sb3_config

    ok = SB3Config(env_id=ENV_ID, n_envs=1024, env_kwargs={"guide": True, "shaping": "field"})
    check_sb3_config(ok, "ppo", "test")
    for shaping in ("euclid", "True", 1):
        bad = SB3Config(env_id=ENV_ID, env_kwargs={"shaping": shaping})
        with pytest.raises(ConfigError, match="env_kwargs.shaping"):
            check_sb3_config(bad, "ppo", "test")
    with pytest.raises(ConfigError, match="n_envs"):
        check_sb3_config(SB3Config(env_id=ENV_ID, n_envs=5000), "ppo", "test")
    with pytest.raises(ConfigError, match="n_envs"):
        check_sb3_config(SB3Config(env_id="AFTIR-Arm-v0", n_envs=128), "ppo", "test")
    her = SB3Config(env_id=ENV_ID, her=True, env_kwargs={"guide": True})
    with pytest.raises(ConfigError, match="guide"):
        check_sb3_config(her, "sac", "test")
    her = SB3Config(env_id=ENV_ID, her=True, env_kwargs={"near_goal": True})
    with pytest.raises(ConfigError, match="env_kwargs.near_goal"):
        check_sb3_config(her, "sac", "test")
    with pytest.raises(ConfigError, match="env_kwargs.near_goal"):
        check_sb3_config(SB3Config(env_id=ENV_ID, env_kwargs={"near_goal": 1}), "ppo", "test")
    # HER samples finished episodes: learning may not start before every env has one
    early = {"learning_starts": 1000}
    check_sb3_config(SB3Config(env_id=ENV_ID, her=True, hyperparameters=early), "sac", "test")
    with pytest.raises(ConfigError, match="learning_starts >= 4800"):
        check_sb3_config(
            SB3Config(env_id=ENV_ID, her=True, n_envs=16, hyperparameters=early), "sac", "test"
        )
    with pytest.raises(ConfigError, match="learning_starts"):
        check_sb3_config(SB3Config(env_id=ENV_ID, her=True), "td3", "test")  # SB3's 100


def test_field_guide_cache_starts_again_and_holders_ask_again():
    from aftir_rl.envs.ftl.fields import FieldGuide

    tank = load_tank("b737_center")
    guide = FieldGuide(tank)
    guide.capacity = 2
    targets = np.array([[200.0, 120.0, 50.0], [30.0, 20.0, 60.0], [150.0, 100.0, 30.0]])
    first = guide.field_ids(targets[:2])
    assert guide.generation == 0 and len(set(first.tolist())) == 2
    again = guide.field_ids(targets[2:])  # a third cell: the cache starts again
    assert guide.generation == 1
    tips = np.array([[0.0, 0.0, 10.0]])
    fresh = FieldGuide(tank)
    expect = fresh(tips, targets[2:], fresh.field_ids(targets[2:]))[0]
    np.testing.assert_allclose(guide(tips, targets[2:], again)[0], expect)
    # an env batch whose ids went void asks again before it observes
    env = ArmFTLVectorEnv(num_envs=2, guide=True)
    env.reset(seed=0)
    batch = env.batch
    capacity = batch.guide.capacity  # the guide is shared by the tank's envs: put it back
    batch.guide.capacity = len(batch.guide)  # full: the next new cell starts it again
    try:
        env.reset(seed=1, options={"target": (150.0, 100.0, 30.0)})
        obs = batch.observation()
    finally:
        batch.guide.capacity = capacity
    to_go = obs[:, -16] * 100
    direct = FieldGuide(tank)
    ids = direct.field_ids(batch.target)
    expect = np.minimum(direct(batch.tip, batch.target, ids)[0], 1000)
    np.testing.assert_allclose(to_go, expect, rtol=1e-5)


def test_field_guides_of_a_process_share_one_budget(monkeypatch):
    """A pool's tanks keep at most ``MAX_GUIDE_VALUES`` together, and every id stays valid."""
    import weakref

    from aftir_rl.core.tank.generate import wing_tank
    from aftir_rl.core.tank.loading import tank_from_mapping
    from aftir_rl.envs.ftl import fields

    monkeypatch.setattr(fields, "_GUIDES", weakref.WeakSet())
    tanks = [tank_from_mapping(wing_tank(2, s), f"wing:2:{s}") for s in (0, 1)]  # not cached
    guides = [fields.field_guide(t) for t in tanks]
    budget = 5 * guides[0].n_points  # about five fields in all
    monkeypatch.setattr(fields, "MAX_GUIDE_VALUES", budget)
    rng = np.random.default_rng(0)
    tips = np.array([[0.0, 0.0, 10.0], [20.0, 5.0, 30.0]])
    for step in range(12):
        k = step % 2
        lo, hi = np.array(tanks[k].box_min) + 20, np.array(tanks[k].box_max) - 20
        targets = rng.uniform(lo, hi, (2, 3))
        ids = guides[k].field_ids(targets)
        kept = sum(len(g) * g.n_points for g in guides)
        assert kept <= budget + guides[k].n_points  # at most one field over, when it was empty
        fresh = fields.FieldGuide(tanks[k])
        np.testing.assert_allclose(
            guides[k](tips, targets, ids)[0], fresh(tips, targets, fresh.field_ids(targets))[0]
        )
    assert guides[0].generation > 0 and guides[1].generation > 0
