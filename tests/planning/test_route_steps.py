"""The route search one state at a time: its moves and its closing, checked independently."""

from __future__ import annotations

import numpy as np
import pytest

from aftir_rl.core.collision import point_clearance
from aftir_rl.core.errors import PlanningError
from aftir_rl.core.tank import load_tank
from aftir_rl.planning.ftl.closing import route_clearance
from aftir_rl.planning.ftl.model import Route, route_points
from aftir_rl.planning.ftl.plan import deploy_route
from aftir_rl.planning.ftl.route import (
    RouteSettings,
    close_route,
    move_set,
    plan_route,
    route_moves,
)

SETTINGS = RouteSettings(leads=(0.0,))


@pytest.fixture(scope="module")
def tank():
    return load_tank("b737_center")


def _planned(tank, target):
    return plan_route(tank, target, None, SETTINGS).route


@pytest.mark.parametrize(
    "target", [(181.5, 111.6, 51.5), (200.0, 100.0, 40.0), (60.0, 130.0, 70.0)]
)
def test_moves_are_clear_exactly_where_the_section_keeps_the_clearance(tank, target):
    """Along a planned route, each move's new section sampled against the exact distance."""
    route = _planned(tank, target)
    l, arm = route.section_length, tank.arm
    need = arm.radius + SETTINGS.margin + SETTINGS.slack
    changes = move_set(SETTINGS)
    for k in range(min(route.n_route_sections, 5)):
        prefix = Route(0.0, route.kappa[:k], l)
        moves = route_moves(tank, prefix, target, SETTINGS)
        last = route.kappa[k - 1] if k else np.zeros(2)
        for j in np.flatnonzero(moves.ok):
            bent = last + changes[j]
            bent *= min(1.0, arm.theta_max / max(np.linalg.norm(bent), 1e-12))  # within θ_max
            np.testing.assert_allclose(moves.kappa[j], bent, atol=1e-9)
            grown = Route(0.0, np.vstack([prefix.kappa, moves.kappa[j]]), l)
            u = k * l + np.linspace(0.0, l, 41)
            clear = point_clearance(tank, route_points(grown, u))
            assert clear.min() >= need - 0.5, (k, j)  # the search samples 10 points a section
            np.testing.assert_allclose(route_points(grown, [(k + 1) * l])[0], moves.end_pos[j])
        for j in np.flatnonzero(~moves.ok):
            grown = Route(0.0, np.vstack([prefix.kappa, last + changes[j]]), l)
            u = k * l + np.linspace(0.0, l, 11)
            assert point_clearance(tank, route_points(grown, u)).min() < need + 0.5, (k, j)


@pytest.mark.parametrize("seed", range(4))
def test_a_closed_route_ends_on_the_target_and_keeps_the_margin(tank, seed):
    """From a planned route's states: when the closing answers, the tip is on the target."""
    rng = np.random.default_rng(seed)
    while True:  # a bay-2 target the planner reaches
        target = rng.uniform([110, 70, 20], [220, 140, 80])
        if point_clearance(tank, target[None])[0] > 15:
            try:
                route = plan_route(tank, target).route
                break
            except PlanningError:
                continue
    answered = 0
    for k in range(route.n_route_sections + 1):
        state = Route(route.lead, route.kappa[:k], route.section_length)
        closed = close_route(tank, state, target)
        if closed is None:
            continue
        answered += 1
        final, clearance = closed
        assert np.linalg.norm(final.tip() - target) < 1e-4
        assert route_clearance(tank, tank.arm, final) == pytest.approx(clearance)
        assert clearance >= SETTINGS.margin + SETTINGS.slack / 2
        keep = max(k - 2, 0)  # at most the last two sections are re-bent
        np.testing.assert_allclose(final.kappa[:keep], route.kappa[:keep])
        plan = deploy_route(tank, target, final)
        assert plan.complete and plan.min_clearance_cm >= 1.0 and plan.tip_error_cm < 0.01
    assert answered >= 1  # the planned route itself closes near its end


def test_the_look_ahead_is_each_moves_own_closing_and_moves(tank):
    """``ahead=True`` (batched) against growing the route by each move and asking again."""
    target = (181.5, 111.6, 51.5)
    route = _planned(tank, target)
    for k in range(route.n_route_sections):
        state = Route(0.0, route.kappa[:k], route.section_length)
        moves = route_moves(tank, state, target, SETTINGS, ahead=True)
        for j in range(len(moves.ok)):
            if not moves.ok[j]:
                assert not moves.closes[j] and moves.onward[j] == 0.0
                continue
            grown = Route(0.0, np.vstack([state.kappa, moves.kappa[j]]), state.section_length)
            closes = close_route(tank, grown, target, SETTINGS) is not None
            assert moves.closes[j] == closes, (k, j)
            assert moves.onward[j] == route_moves(tank, grown, target, SETTINGS).ok.mean()
