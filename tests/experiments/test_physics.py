"""The physics check: the Cosserat rod against closed forms, then on planned motions.

The rod (PyElastica) is checked where the answer is known without it: a straight cantilever
under its own weight sags ``w·x²(6L² − 4Lx + x²)/(24·E·I)`` (Euler-Bernoulli, plus the small
Timoshenko shear term ``w·(L·x − x²/2)/(α·G·A)``); a body with imposed curvature and no load
rests on the constant-curvature arcs (forward kinematics); a straight body pushed along its axis
moves rigidly. Then a planned motion simulated without gravity must give back the kinematic body
and its python-fcl clearance, and with gravity sag downwards.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from aftir_rl.core.config import DEFAULT_MARGIN
from aftir_rl.core.errors import ConfigError, PhysicsError
from aftir_rl.core.robot import body_points
from aftir_rl.core.rod import RodProperties
from aftir_rl.core.tank import load_tank

pytest.importorskip("elastica")
physics = pytest.importorskip("aftir_rl.experiments.physics")
rod_model = pytest.importorskip("aftir_rl.experiments.rod_model")

L_SECTION = 50.0


def _straight(n: int, dis: float, model: rod_model.RodModel) -> tuple[np.ndarray, np.ndarray]:
    return rod_model.kinematic_rod(dis, np.zeros(n), np.zeros(n), L_SECTION, model.k)


@pytest.mark.parametrize("dis", [0.0, -37.0, 25.0])
def test_a_cantilever_sags_as_the_closed_form(dis):
    """Gravity across a straight arm clamped at the floor: the beam's deflection curve."""
    n, props = 4, RodProperties()
    model = rod_model.RodModel(n, L_SECTION, 2.5, props, gravity_direction=(-1.0, 0.0, 0.0))
    nodes, frames = _straight(n, dis, model)
    model.set_posture(nodes, frames)
    model.relax(tolerance_cm=1e-4)
    body, _ = model.body()
    free = nodes[:, 2] >= 0  # the part above the floor, measured from where it leaves it
    x = (nodes[free, 2] - max(0.0, dis)) / 100  # m from the clamp
    span = x[-1]
    w = props.mass_per_length * props.gravity
    bend = w * x**2 * (6 * span**2 - 4 * span * x + x**2) / (24 * props.bending_stiffness)
    shear = w * (span * x - x**2 / 2) / props.shear_stiffness
    expected = (bend + shear) * 100  # cm, along -x
    tip = expected[-1]
    assert tip > 0.25  # a sag worth measuring
    assert abs(-body[-1, 0] - tip) <= 0.02 * tip
    assert np.abs(-body[free, 0] - expected).max() <= 0.02 * tip
    # the plain Euler-Bernoulli figure w·L⁴/(8·E·I) is within 2% as well (shear adds <0.5%)
    assert abs(-body[-1, 0] - w * span**4 / (8 * props.bending_stiffness) * 100) <= 0.02 * tip


def test_imposed_curvature_rests_on_the_constant_curvature_arcs():
    """No gravity: from a straight start, the rod relaxes onto the kinematic body (0.1 cm)."""
    rng = np.random.default_rng(7)
    n = 4
    model = rod_model.RodModel(n, L_SECTION, 2.5, RodProperties(gravity=0.0))
    _, flat = _straight(n, 10.0, model)
    start = np.ascontiguousarray(flat.transpose(2, 1, 0))  # straight, as PyElastica stores it
    for _ in range(3):
        theta, phi = rng.uniform(-1.5, 1.5, n), rng.uniform(-np.pi, np.pi, n)
        nodes, frames = rod_model.kinematic_rod(10.0, theta, phi, L_SECTION, model.k)
        model.set_posture(nodes, frames, start)
        model.relax(tolerance_cm=1e-3)
        body, _ = model.body()
        arcs = body_points(10.0, theta, phi, L_SECTION, model.k)  # forward kinematics
        assert np.linalg.norm(body - arcs, axis=1).max() < 0.1


def test_a_push_along_the_axis_moves_the_body_rigidly():
    """Gravity along the axis, the module pushing: every node at its place on the axis."""
    n = 3
    model = rod_model.RodModel(n, L_SECTION, 2.5, RodProperties())
    previous = None
    for dis in (-120.0, -80.0, -30.0, 0.0, 20.0):
        nodes, frames = _straight(n, dis, model)
        start = None if previous is None else previous[1]
        model.set_posture(nodes, frames, start)
        model.relax(tolerance_cm=1e-4)
        previous = model.body()
        arc = np.linspace(0, n * L_SECTION, len(nodes))
        expected = np.stack([0 * arc, 0 * arc, dis + arc], axis=1)
        # the weight compresses the rod by m·g·L/(E·A) ~ 1e-5: far below 0.01 cm
        assert np.abs(previous[0] - expected).max() < 0.01


def test_the_clamp_moves_with_the_floor_crossing():
    """The clamp sits where the body crosses the floor, with a joint between half and one and a
    half elements of free rod."""
    z = np.array([-12.0, -2.0, 8.0, 18.0])
    assert rod_model._clamp(z, 0.0) == (2, pytest.approx(0.5 + 0.8))  # 8 cm above + half
    assert rod_model._clamp(z + 7.0, 0.0) == (1, pytest.approx(1.0))
    assert rod_model._clamp(z + 2.0, 0.0) == (1, pytest.approx(0.5))  # a node on the floor
    assert rod_model._clamp(z + 20.0, 0.0) == (0, 0.5)
    assert rod_model._clamp(z - 30.0, 0.0)[0] == 3


def test_the_clearance_curve_lies_on_the_arcs():
    """Where a chord cuts 0.39 cm inside an arc, the curve the clearance is taken on does not;
    turned and moved with its element, its bow goes along."""
    rng = np.random.default_rng(3)
    theta, phi = rng.uniform(-1.57, 1.57, 4), rng.uniform(-np.pi, np.pi, 4)
    k, m = rod_model.ELEMENTS_PER_SECTION, rod_model.CURVE_POINTS
    nodes, frames = rod_model.kinematic_rod(-20.0, theta, phi, L_SECTION, k)
    directors = np.ascontiguousarray(frames.transpose(2, 1, 0))
    arcs = body_points(-20.0, theta, phi, L_SECTION, k * m)
    curve = rod_model.body_curve(nodes, directors, arcs, frames)
    dense = body_points(-20.0, theta, phi, L_SECTION, 2000)
    gaps = np.linalg.norm(curve[:, None] - dense[None], axis=2).min(axis=1)
    assert len(curve) == 4 * k * m + 1 and gaps.max() < 1e-3
    mids = (nodes[1:] + nodes[:-1]) / 2  # a chord's middle: up to 0.39 cm inside the arc
    assert np.linalg.norm(mids[:, None] - dense[None], axis=2).min(axis=1).max() > 0.3
    # the whole body turned about the base and moved: the curve turns and moves with it
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    moved = rod_model.body_curve(
        nodes @ turn.T + 5.0,
        np.einsum("ij,eja->iae", turn, frames).transpose(1, 0, 2),
        arcs,
        frames,
    )
    assert np.allclose(moved, curve @ turn.T + 5.0, atol=1e-9)


def test_instants_are_bounded_by_the_entries_and_a_cap():
    t = np.array([0.0, 0.4, 0.9, 1.0, 2.5, 2.6, 7.0])
    assert physics.snapshot_entries(t, 1.0) == [0, 3, 4, 6]
    assert physics.snapshot_entries(t, 1.0, also=(5,)) == [0, 3, 4, 5, 6]
    huge = np.array([0.0, 1e300])  # a file's times: never one instant per second of them
    assert physics.snapshot_entries(huge, 0.1) == [0, 1]
    from types import SimpleNamespace

    n = 2
    many = SimpleNamespace(
        timing=SimpleNamespace(t=np.arange(physics.MAX_SNAPSHOTS + 1.0)),
        dis=np.zeros(physics.MAX_SNAPSHOTS + 1),
        theta=np.zeros((physics.MAX_SNAPSHOTS + 1, n)),
        phi=np.zeros((physics.MAX_SNAPSHOTS + 1, n)),
        section_length=L_SECTION,
    )
    with pytest.raises(PhysicsError, match="more than 5,000; simulate fewer"):
        physics.simulate_motion(many, load_tank("b737_center"), every_s=1.0)


def test_rod_properties_from_yaml_are_checked():
    assert RodProperties.from_mapping(None, "arm.rod") == RodProperties()
    got = RodProperties.from_mapping({"bending_stiffness": 500, "gravity": 0}, "arm.rod")
    assert got.bending_stiffness == 500 and got.gravity == 0
    for bad in ({"stiffness": 1}, {"mass_per_length": 0}, {"axial_stiffness": -1},
                {"bending_stiffness": 1e13}, {"gravity": "down"}):  # fmt: skip
        with pytest.raises(ConfigError):
            RodProperties.from_mapping(bad, "arm.rod")
    assert RodProperties().scaled(2.0).bending_stiffness == 2 * RodProperties().bending_stiffness


@pytest.fixture(scope="module")
def timed_run(tmp_path_factory):
    """A timed planner motion to a target in bay 2 (through the hatch)."""
    pytest.importorskip("toppra")
    from aftir_rl.experiments.execution import read_timed
    from aftir_rl.planning.ftl.plan import plan_motion

    plan = plan_motion(load_tank("b737_center"), (181.5, 111.6, 51.5))
    assert plan.complete
    folder = tmp_path_factory.mktemp("physics") / "motion"
    folder.mkdir()
    (folder / "trajectory.json").write_text(json.dumps(plan.to_json()))
    (folder / "summary.json").write_text(json.dumps({"tank": "b737_center"}))
    return folder, read_timed(folder)


@pytest.mark.slow
def test_without_gravity_the_simulated_motion_is_the_kinematic_one(timed_run):
    """Gravity off: the body stays on the arcs, and its clearance is python-fcl's of the arm."""
    _, run = timed_run
    tank = load_tank("b737_center")
    report = physics.simulate_motion(run, tank, rod=RodProperties(gravity=0.0), every_s=10.0)
    assert max(report.deviation_max) < 0.02
    gaps = np.abs(np.array(report.clearance) - np.array(report.kinematic_clearance))
    assert gaps.max() < 0.05  # a curve through the nodes against 20 capsules per section
    assert report.held and report.entries[-1] == len(run.dis) - 1


@pytest.mark.slow
def test_with_gravity_the_body_sags_down_and_softer_sags_more(timed_run):
    _, run = timed_run
    tank = load_tank("b737_center")
    stiff = physics.simulate_motion(run, tank, every_s=5.0)
    soft = physics.simulate_motion(run, tank, rod=RodProperties().scaled(0.5), every_s=5.0)
    for report in (stiff, soft):
        sag = report.bodies[-1] - body_points(
            run.dis[-1], run.theta[-1], run.phi[-1], run.section_length, 5
        )
        assert sag[-1, 2] < -0.1 and abs(sag[-1, 2]) > 0.9 * np.linalg.norm(sag[-1])
    # linear in the load for small sags: half the stiffness, about twice the sag
    ratio = soft.tip_error[-1] / stiff.tip_error[-1]
    assert 1.8 < ratio < 2.2
    assert stiff.summary()["unsettled_snapshots"] == 0
    again = physics.simulate_motion(run, tank, every_s=5.0)
    assert again.clearance == stiff.clearance  # the same inputs, the same answer


@pytest.mark.slow
def test_a_diverging_warm_start_is_simulated_again_from_the_kinematic_body(timed_run, monkeypatch):
    _, run = timed_run
    tank = load_tank("b737_center")
    plain = physics.simulate_motion(run, tank, every_s=10.0)
    relax, failed = rod_model.RodModel.relax, []

    def once(self, tolerance_cm=rod_model.TOLERANCE_CM):
        if not failed and self.steps > 0:
            failed.append(True)
            raise PhysicsError("diverged")
        return relax(self, tolerance_cm)

    monkeypatch.setattr(rod_model.RodModel, "relax", once)
    again = physics.simulate_motion(run, tank, every_s=10.0)
    assert failed and again.entries == plain.entries
    assert np.allclose(again.clearance, plain.clearance, atol=0.02)


@pytest.mark.slow
def test_simulate_cli_writes_physics_json_and_judges_the_margin(timed_run, capsys, tmp_path):
    from aftir_rl.cli import simulate

    folder, run = timed_run
    assert simulate.main([str(folder), "--every", "5"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1 and "margin held" in out
    data = json.loads((folder / physics.PHYSICS_FILE).read_text())
    assert data["summary"]["margin_held"] and data["summary"]["margin_cm"] == DEFAULT_MARGIN
    assert data["settings"]["elements_per_section"] == rod_model.ELEMENTS_PER_SECTION
    nodes = rod_model.ELEMENTS_PER_SECTION * run.theta.shape[1] + 1
    assert all(len(snap["body"]) == nodes for snap in data["snapshots"])
    # a body a hundred times softer sags onto the tank: exit 1, one line
    assert simulate.main([str(folder), "--every", "10", "--stiffness", "0.01"]) == 1
    assert "MARGIN LOST" in capsys.readouterr().out
    # --replan may not write over the run it reads
    assert simulate.main([str(folder), "--stiffness", "0.01", "--replan", str(folder)]) == 2


@pytest.mark.slow
def test_a_motion_that_loses_the_margin_is_planned_again_and_keeps_it(tmp_path):
    """The reference corner (-50, 72, 90) sags onto bay 2's floor stringer with the default
    body (bench_physics: 0.75 cm); planned again with the margin it lacked, it keeps 1 cm."""
    pytest.importorskip("toppra")
    from aftir_rl.cli import simulate
    from aftir_rl.planning.ftl.plan import plan_motion

    tank = load_tank("b737_center")
    plan = plan_motion(tank, (-50.0, 72.0, 90.0))
    folder = tmp_path / "corner"
    folder.mkdir()
    (folder / "trajectory.json").write_text(json.dumps(plan.to_json()))
    again = tmp_path / "again"
    assert (
        simulate.main([str(folder), "--every", "2", "--replan", str(again), "--no-progress"]) == 0
    )
    lost = json.loads((folder / physics.PHYSICS_FILE).read_text())["summary"]
    kept = json.loads((again / physics.PHYSICS_FILE).read_text())["summary"]
    assert not lost["margin_held"] and lost["least_clearance_cm"] < DEFAULT_MARGIN
    assert kept["margin_held"] and kept["least_clearance_cm"] >= DEFAULT_MARGIN
    planned = json.loads((again / "summary.json").read_text())["planned_margin_cm"]
    new = json.loads((again / "trajectory.json").read_text())
    assert (
        new["margin_cm"] == planned > DEFAULT_MARGIN + DEFAULT_MARGIN - lost["least_clearance_cm"]
    )
    from aftir_rl.cli import check

    assert check.main([str(again)]) == 0  # the new motion passes the kinematic check too
