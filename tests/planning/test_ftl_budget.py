"""The follow-the-leader planner's budgets: work, not time, so a plan is the same under any load.

The route search stops on candidate sections evaluated (``max_expanded``), never on the clock;
a wall-clock guard (``max_seconds``, off by default) reports a timeout, never "no route".
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np
import pytest

from aftir_rl.core.errors import ConfigError, PlanningError, PlanningTimeout
from aftir_rl.experiments.suite import suite_targets
from aftir_rl.planning.ftl.plan import MAX_EXPANDED_TOTAL, SEARCH_VARIANTS, plan_motion, warm_up
from aftir_rl.planning.ftl.route import RouteSettings, plan_route, search_route

#: 10 cm behind the baffle, 26 cm beside the hatch: only a last-resort setting reaches it.
BEHIND_BAFFLE = (54.4, 72.2, 45.3)


def _outcome(plan):
    """What must not depend on the machine: the verdict, the route, the motion, the work."""
    if not plan.complete:
        return (False, plan.reason, plan.expanded)
    route, motion = plan.motion.route, plan.motion
    return (
        True,
        route.lead,
        route.kappa.tobytes(),
        motion.dis.tobytes(),
        motion.theta.tobytes(),
        motion.phi.tobytes(),
        plan.expanded,
    )


@pytest.mark.slow
def test_plans_are_the_same_while_other_processes_load_the_cores(tank):
    warm_up(tank)  # compile first: compiling under load must not change a plan either
    targets = [BEHIND_BAFFLE, (230.0, 140.0, 90.0)]
    targets += [tuple(t) for t in suite_targets(tank, 2, seed=5, region=tank.bay(1))]
    targets += [tuple(t) for t in suite_targets(tank, 2, seed=5, region=tank.bay(2))]
    alone = [_outcome(plan_motion(tank, t)) for t in targets]
    assert alone[0][0], "the target behind the baffle has a motion"
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        time.sleep(0.5)  # let them take the cores
        assert all(p.poll() is None for p in spinners)
        loaded = [_outcome(plan_motion(tank, t)) for t in targets]
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    assert loaded == alone


def test_the_work_budget_stops_a_search_the_same_way_each_time(tank):
    tight = RouteSettings(max_expanded=500)
    first = search_route(tank, BEHIND_BAFFLE, settings=tight)
    again = search_route(tank, BEHIND_BAFFLE, settings=tight)
    assert first.result is None and 0 < first.expanded <= 500
    assert (again.expanded, again.reason) == (first.expanded, first.reason)
    assert "work budget of 500 candidate sections ran out" in first.reason
    with pytest.raises(PlanningError, match="work budget") as caught:
        plan_route(tank, BEHIND_BAFFLE, settings=tight)
    assert not isinstance(caught.value, PlanningTimeout)


def test_a_search_within_its_budget_reports_the_work_it_took(tank):
    first = replace(SEARCH_VARIANTS[0], margin=1.0)  # what plan_motion tries first
    found = plan_route(tank, (230.0, 140.0, 90.0), settings=first)
    assert 0 < found.expanded <= first.max_expanded
    plan = plan_motion(tank, (230.0, 140.0, 90.0), margin=1.0)
    assert plan.complete and plan.expanded >= found.expanded


def test_the_total_budget_of_a_motion_bounds_every_setting_together(tank):
    plan = plan_motion(tank, BEHIND_BAFFLE, max_expanded=20_000)
    assert not plan.complete and not plan.timed_out
    assert 0 < plan.expanded <= 20_000
    assert "work budget" in plan.reason


def test_the_wall_clock_guard_reports_a_timeout_not_no_route(tank):
    with pytest.raises(PlanningTimeout, match="^Planning timed out") as caught:
        plan_route(tank, BEHIND_BAFFLE, settings=RouteSettings(max_seconds=1e-9))
    assert "no route" not in str(caught.value)
    plan = plan_motion(tank, BEHIND_BAFFLE, max_seconds=1e-9)
    assert not plan.complete and plan.timed_out
    assert plan.reason.startswith("Planning timed out") and "no route" not in plan.reason
    assert plan.to_json()["timed_out"] is True
    assert "timed_out" not in plan_motion(tank, (230.0, 140.0, 90.0)).to_json()


@pytest.mark.parametrize(
    "knobs", [{"max_expanded": 0}, {"max_seconds": 0.0}, {"max_seconds": math.nan}]
)
def test_a_budget_that_is_not_one_is_refused(tank, knobs):
    with pytest.raises(ConfigError, match=next(iter(knobs))):
        plan_route(tank, BEHIND_BAFFLE, settings=RouteSettings(**knobs))
    with pytest.raises(ConfigError, match=next(iter(knobs))):
        plan_motion(tank, BEHIND_BAFFLE, **knobs)


def test_the_default_budget_is_above_what_the_widest_setting_can_evaluate(tank):
    # 2 corridors x 25 moves x (the first depth's leads + the other depths' states)
    def most(s: RouteSettings) -> int:
        return 2 * 25 * (len(s.leads) + (tank.arm.max_sections - 1) * s.beam_width)

    assert max(map(most, SEARCH_VARIANTS)) <= RouteSettings().max_expanded
    assert sum(map(most, SEARCH_VARIANTS)) <= MAX_EXPANDED_TOTAL
    assert np.all([s.max_seconds is None for s in SEARCH_VARIANTS])
