"""``AFTIR-ArmFTL-v0`` with a pool of generated tanks: a tank per episode, one goal space."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import aftir_rl  # noqa: F401  (registers the envs)
from aftir_rl.core.errors import ConfigError, InvalidActionError
from aftir_rl.core.tank import load_tank
from aftir_rl.envs.ftl.env import ArmFTLEnv, ArmFTLVectorEnv
from aftir_rl.envs.ftl.pool import MAX_POOL, pool_specs
from aftir_rl.envs.ftl.pool_vector import ArmFTLPoolVectorEnv
from aftir_rl.rl.sb3.evaluation import evaluation_targets


def test_each_episode_draws_a_tank_of_the_pool():
    env = gym.make("AFTIR-ArmFTL-v0", tank="wing:2:0-3", bay=2)
    seen = {}
    for episode in range(10):
        obs, info = env.reset(seed=episode)
        assert env.observation_space.contains(obs)
        tank = load_tank(info["tank"])
        lo, hi = tank.bay(2)
        assert np.all((info["target"] > lo) & (info["target"] < hi))  # this tank's bay 2
        assert tank.distance(info["target"]) >= 5.0
        obs, *_ = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        seen.setdefault(info["tank"], episode)
    assert len(seen) >= 3
    again = gym.make("AFTIR-ArmFTL-v0", tank="wing:2:0-3", bay=2)
    for episode in (0, 5):  # a seed gives the same tank and target
        _, first = env.reset(seed=episode)
        _, second = again.reset(seed=episode)
        assert first["tank"] == second["tank"]
        np.testing.assert_array_equal(first["target"], second["target"])


def test_sync_vector_envs_draw_their_own_tanks():
    envs = gym.make_vec("AFTIR-ArmFTL-v0", 2, vectorization_mode="sync", tank="wing:2:0-7", bay=1)
    _, info = envs.reset(seed=[3, 4])
    assert len(info["tank"]) == 2
    envs.step(envs.action_space.sample())


def test_pools_are_refused_where_one_tank_is_needed():
    with pytest.raises(ConfigError, match="one tank per group of rows"):
        ArmFTLVectorEnv(4, tank="wing:2:0-3")
    with pytest.raises(ConfigError, match="is a pool of generated tanks"):
        load_tank("wing:2:0-3")
    with pytest.raises(ConfigError, match=f"1 to {MAX_POOL} seeds"):
        pool_specs("wing:2:5-1")
    with pytest.raises(ConfigError, match=f"1 to {MAX_POOL} seeds"):
        pool_specs(f"wing:2:0-{MAX_POOL}")
    assert pool_specs("wing:2:7") is None and pool_specs("b737_center") is None


def test_batched_pool_rows_are_single_envs_of_their_tanks():
    """Row ``i`` (SameStep autoreset) has the transitions of a single env of its tank seeded
    ``seed + i``; groups of 2, 2 and 1 rows for a pool of 3 tanks and 5 rows."""
    b, steps, pool = 5, 80, "wing:2:0-2"
    venv = gym.make_vec(
        "AFTIR-ArmFTL-v0",
        b,
        tank=pool,
        guide=True,
        max_episode_steps=20,
        autoreset_mode="SameStep",
    )
    assert isinstance(venv, ArmFTLPoolVectorEnv)
    obs, info = venv.reset(seed=7)
    assert info["tank"] == ["wing:2:0", "wing:2:0", "wing:2:1", "wing:2:1", "wing:2:2"]
    assert venv.observation_space.contains(obs)
    single = [ArmFTLEnv(tank=name, guide=True) for name in info["tank"]]
    for i, env in enumerate(single):
        o, first = env.reset(seed=7 + i)
        np.testing.assert_allclose(first["target"], info["target"][i], atol=1e-5)  # float32 kept
        np.testing.assert_array_equal(o["observation"], obs["observation"][i])
    rng = np.random.default_rng(3)
    ended = 0
    for _ in range(steps):
        a = rng.uniform(-1, 1, (b, 3)).astype(np.float32)
        a[:, 2] = np.abs(a[:, 2])
        nxt, r, term, trunc, info = venv.step(a)
        for i, env in enumerate(single):
            o, r1, te, _, _ = env.step(a[i])
            assert r1 == r[i] and te == term[i]
            if term[i] or trunc[i]:
                ended += 1
                assert info["_final_obs"][i]
                for key in o:
                    np.testing.assert_array_equal(info["final_obs"][i][key], o[key])
                o, _ = env.reset()
            for key in o:
                np.testing.assert_array_equal(nxt[key][i], o[key])
    assert ended >= b


def test_batched_pool_options_and_bad_input():
    venv = ArmFTLPoolVectorEnv(4, tank="wing:2:0-1", bay=1)
    _, info = venv.reset(seed=0)
    for i, name in enumerate(info["tank"]):
        assert load_tank(name).distance(info["target"][i]) >= 5.0
    own = info["target"].copy()
    _, again = venv.reset(options={"target": own})
    np.testing.assert_array_equal(again["target"], own)
    with pytest.raises(InvalidActionError):
        venv.step(np.zeros((3, 3), np.float32))
    with pytest.raises(ConfigError, match="seeds"):
        venv.reset(seed=[1, 2])
    with pytest.raises(ConfigError, match="needs a pool"):
        ArmFTLPoolVectorEnv(2, tank="wing:2:0")


def test_single_env_tank_option_and_pool_evaluation_targets():
    env = gym.make("AFTIR-ArmFTL-v0", tank="wing:2:0-2", bay=2)
    for option, name in ((2, "wing:2:2"), ("wing:2:1", "wing:2:1")):
        _, info = env.reset(seed=0, options={"tank": option})
        assert info["tank"] == name
    for bad in (3, -1, "wing:2:9", True):
        with pytest.raises(ConfigError, match="not in the pool"):
            env.reset(options={"tank": bad})
    with pytest.raises(ConfigError, match="unknown reset option 'tank'"):
        gym.make("AFTIR-ArmFTL-v0", tank="wing:2:0").reset(options={"tank": 0})
    targets = evaluation_targets("AFTIR-ArmFTL-v0", 6, 11, {"tank": "wing:2:0-2", "bay": 2})
    for i, target in enumerate(targets):  # target i lies in tank i mod 3
        tank = load_tank(f"wing:2:{i % 3}")
        lo, hi = tank.bay(2)
        assert np.all((target > lo) & (target < hi)) and tank.distance(target) >= 5.0


def _stream_run(mode: str, steps: int = 120, seed: int = 3) -> tuple[list, ArmFTLPoolVectorEnv]:
    env = gym.make_vec(
        "aftir_rl:AFTIR-ArmFTL-v0", num_envs=6, tank="wing:2:700+", tanks_at_once=2,
        tank_episodes=5, autoreset_mode=mode, max_episode_steps=25, bay=1,
    )  # fmt: skip
    env.reset(seed=seed)
    actions = np.random.default_rng(1).uniform(-1, 1, (steps, 6, 3)).astype(np.float32)
    record = []
    for a in actions:
        before = list(env.row_tanks)
        obs, reward, terminated, truncated, info = env.step(a)
        record.append((before, list(env.row_tanks), obs, reward, terminated, truncated, info))
    return record, env


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_a_stream_moves_each_group_on_to_unused_wings(mode):
    record, env = _stream_run(mode)
    seen = [t for step in record for t in dict.fromkeys(step[1])]
    tanks = list(dict.fromkeys(seen))
    assert len(tanks) >= 5, tanks  # the two first wings, then new ones
    assert tanks == [f"wing:2:{700 + i}" for i in range(len(tanks))]  # in order, none twice
    assert env.tanks_met == len(tanks)
    swaps = 0
    for t, (before, after, *_) in enumerate(record):
        for new_tank in dict.fromkeys(after[i] for i in range(6) if before[i] != after[i]):
            swaps += 1
            moved = [i for i in range(6) if after[i] == new_tank]
            _check_moved(mode, record, t, moved, new_tank)
    assert swaps >= 3
    assert env.observation_space.contains(record[-1][2])


def _check_moved(mode: str, record: list, t: int, moved: list[int], new_tank: str) -> None:
    """The rows of a group that has just moved on to ``new_tank`` at step ``t``."""
    _, _, obs, _, terminated, truncated, info = record[t]
    assert np.all((terminated | truncated)[moved])  # every row of the group ends there
    tank = load_tank(new_tank)
    lo, hi = tank.bay(1)
    if mode == "SameStep":  # the returned rows are the new tank's first observations
        assert info["_final_obs"][moved].all()
        goals = obs["desired_goal"][moved]
        np.testing.assert_allclose(
            obs["achieved_goal"][moved], obs["achieved_goal"][moved][:1].repeat(len(moved), 0)
        )
    elif t + 1 < len(record):  # the next step starts them there, reward 0
        nxt = record[t + 1]
        assert np.all(nxt[3][moved] == 0) and not np.any((nxt[4] | nxt[5])[moved])
        goals = nxt[2]["desired_goal"][moved]
    else:
        return
    assert np.all((goals > lo) & (goals < hi)), (goals, lo, hi)  # targets of its bay 1
    assert all(tank.distance(g) > 0 for g in goals)


def test_a_seeded_stream_repeats_and_starts_again_on_a_seeded_reset():
    first, env = _stream_run("NextStep", steps=80)
    second, _ = _stream_run("NextStep", steps=80)
    for a, b in zip(first, second):
        assert a[1] == b[1]
        np.testing.assert_array_equal(a[2]["observation"], b[2]["observation"])
        np.testing.assert_array_equal(a[3], b[3])
    assert env.row_tanks != ["wing:2:700"] * 3 + ["wing:2:701"] * 3
    env.reset(seed=3)
    assert env.row_tanks == ["wing:2:700"] * 3 + ["wing:2:701"] * 3


def test_streams_are_refused_where_they_cannot_run():
    with pytest.raises(ConfigError, match="the batched env's"):
        ArmFTLVectorEnv(num_envs=2, tank="wing:3:5+")  # (make_vec gives the pool env)
    with pytest.raises(ConfigError, match="is a stream of generated wings"):
        load_tank("wing:3:5+")
    with pytest.raises(ConfigError, match="1 to 8 bays"):
        gym.make_vec("AFTIR-ArmFTL-v0", 2, tank="wing:9:5+")
    with pytest.raises(ConfigError, match="tank_episodes must be"):
        gym.make_vec("AFTIR-ArmFTL-v0", 2, tank="wing:3:5+", tank_episodes=0)
    with pytest.raises(ConfigError, match="a stream's"):
        gym.make_vec("AFTIR-ArmFTL-v0", 2, tank="wing:3:5-6", tank_episodes=3)


def test_the_family_box_holds_every_generated_wing():
    from aftir_rl.core.tank.generate import wing_family_box, wing_tank

    for bays in (1, 2, 3, 5, 8):
        lo, hi = wing_family_box(bays)
        for seed in range(60):
            box = wing_tank(bays, seed)["box"]
            assert np.all(np.asarray(box["min"]) >= lo) and np.all(np.asarray(box["max"]) <= hi)


def test_a_single_env_of_a_stream_is_its_first_wings_as_a_pool_with_the_streams_goal_space():
    single = gym.make("AFTIR-ArmFTL-v0", tank="wing:2:40+", tank_episodes=3, tanks_at_once=2)
    assert single.unwrapped.pool.names == [f"wing:2:{40 + i}" for i in range(16)]
    batched = gym.make_vec("AFTIR-ArmFTL-v0", 4, tank="wing:2:40+", tanks_at_once=2)
    pool = gym.make("AFTIR-ArmFTL-v0", tank="wing:2:900-903")
    for other in (batched.single_observation_space, pool.observation_space):
        for key in ("achieved_goal", "desired_goal"):
            np.testing.assert_array_equal(single.observation_space[key].low, other[key].low)
            np.testing.assert_array_equal(single.observation_space[key].high, other[key].high)


def test_the_round_family_has_only_round_ways_through_its_ribs():
    """``round:BAYS:SEED``: every rib an oval access hole and the round ones of 2 or 3 tried
    that fit beside it; named so."""
    from aftir_rl.core.tank.plate import Plate

    circles = {"wing": 0, "round": 0}
    for seed in range(40):
        for family in circles:
            circles[family] += sum(
                h.shape == "circle" for s in load_tank(f"{family}:3:{seed}").solids
                if isinstance(s, Plate) for h in s.holes
            )  # fmt: skip
    for seed in range(6):
        tank = load_tank(f"round:3:{seed}")
        assert tank.name == f"round_3bay_s{seed}"
        ribs = [s for s in tank.solids if isinstance(s, Plate)]
        assert len(ribs) == 2
        for rib in ribs:
            shapes = sorted(h.shape for h in rib.holes)
            assert shapes.count("oval") == 1 and set(shapes) <= {"oval", "circle"}
            assert shapes.count("circle") <= 3
    assert circles["round"] > 1.5 * circles["wing"]  # 87 and 52 in 80 ribs each
    assert pool_specs("round:2:4-5") == ["round:2:4", "round:2:5"]


def test_a_mixed_stream_draws_each_wings_family_and_bays_from_its_seed():
    from aftir_rl.core.tank.generate import MIX_BAYS, mixed_kind, wing_family_box
    from aftir_rl.envs.ftl.pool import stream_spec

    stream = stream_spec("mix:300+")
    assert (stream.first, stream.family, stream.bays, stream.text) == (300, None, None, "mix:300+")
    kinds = [mixed_kind(300 + k) for k in range(200)]
    assert [stream.spec_at(k) for k in range(200)] == [
        f"{f}:{b}:{300 + k}" for k, (f, b) in enumerate(kinds)
    ]
    assert {f for f, _ in kinds} == {"wing", "round"}
    assert {b for _, b in kinds} == set(range(MIX_BAYS[0], MIX_BAYS[1] + 1))
    assert stream_spec("round:2:7+").spec_at(3) == "round:2:10"
    # the batched env moves its groups along it; its goal space holds the largest wings
    venv = gym.make_vec("AFTIR-ArmFTL-v0", 4, tank="mix:300+", tanks_at_once=2)
    assert venv.row_tanks == [stream.spec_at(0)] * 2 + [stream.spec_at(1)] * 2
    lo, hi = wing_family_box(MIX_BAYS[1])
    goal = venv.single_observation_space["desired_goal"]
    assert np.all(goal.low <= lo - 99) and np.all(goal.high >= hi + 99)
    # one env cannot take it as a pool: it mixes families and bays
    with pytest.raises(ConfigError, match="a mixed stream"):
        gym.make("AFTIR-ArmFTL-v0", tank="mix:300+")
    with pytest.raises(ConfigError, match="is a stream"):
        load_tank("mix:300+")
