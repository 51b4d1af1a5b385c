"""Prioritised level replay: PLR's replay distribution in closed form, and a run that uses it."""

from __future__ import annotations

import numpy as np
import pytest

from aftir_rl.core.errors import ConfigError
from aftir_rl.rl.level_replay import LevelReplay


def test_the_replay_distribution_is_plrs_rank_and_staleness_mixture():
    plr = LevelReplay(temperature=0.5, staleness=0.25, min_levels=1)
    for name, score in (("a", 0.2), ("b", 0.6), ("c", 0.4)):
        plr.update(name, score)  # visits 1, 2, 3
    names, p = plr.probabilities()
    # ranks b=1, c=2, a=3: (1/rank)^(1/β) = 1, 1/4, 1/9; staleness c - C_i = 2, 1, 0
    by_score = np.array([1 / 9, 1, 1 / 4]) / (1 + 1 / 4 + 1 / 9)
    by_age = np.array([2, 1, 0]) / 3
    np.testing.assert_allclose(p, 0.75 * by_score + 0.25 * by_age)
    assert names == ["a", "b", "c"] and p.sum() == pytest.approx(1.0)


def test_replay_waits_for_enough_levels_and_keeps_the_highest_scored():
    rng = np.random.default_rng(0)
    plr = LevelReplay(replay=1.0, min_levels=3, size=3)
    plr.update("a", 0.5)
    plr.update("b", 0.1)
    assert plr.choose(rng) is None  # 2 of 3 levels scored
    plr.update("c", 0.9)
    assert {plr.choose(rng) for _ in range(200)} == {"a", "b", "c"}
    plr.update("d", 0.7)  # past size 3: the lowest scored (b) is let go
    assert set(plr.levels) == {"a", "c", "d"}
    never = LevelReplay(replay=0.0, min_levels=1)
    never.update("a", 1.0)
    assert all(never.choose(rng) is None for _ in range(50))
    with pytest.raises(ConfigError):
        LevelReplay(replay=1.5)
    with pytest.raises(ConfigError):
        LevelReplay(temperature=0.0)


@pytest.mark.slow
def test_a_stream_run_with_replay_revisits_wings_it_has_met(monkeypatch):
    """Every replayed visit is in a wing the stream met before; the new wings come in order."""
    import aftir_rl.rl.route_policy as route_policy
    from aftir_rl.envs.ftl.route_env import ArmRouteEnv

    monkeypatch.setattr(route_policy, "REPLAY_FIT_EVERY", 4)
    visited = []
    original = ArmRouteEnv.in_tank
    monkeypatch.setattr(
        ArmRouteEnv, "in_tank", lambda self, tank: visited.append(tank) or original(self, tank)
    )
    env = ArmRouteEnv(tank="wing:2:700+", tank_episodes=2, leads=(0.0,))
    plr = LevelReplay(replay=0.5, min_levels=2)
    _, stats = route_policy.train_route_policy(env, routes=16, updates=50, level_replay=plr)
    met = [f"wing:2:{700 + k}" for k in range(env.tanks_met)]
    assert stats.replays == len(visited) >= 1 and set(visited) <= set(met)
    assert env.tanks_met + stats.replays == 8  # 16 routes, 2 a visit
    assert set(plr.levels) == set(met) and stats.rounds[0]["replayed_visits"] == stats.replays
    with pytest.raises(ConfigError, match="needs a stream"):
        route_policy.train_route_policy(
            ArmRouteEnv(tank="wing:2:700", leads=(0.0,)), routes=2, level_replay=plr
        )
