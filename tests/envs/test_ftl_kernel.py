"""The compiled kernels of AFTIR-ArmFTL-v0 against the package's numpy definitions.

Each reference below is the numpy pipeline the kernels replaced, written from the package's own
primitives (:func:`body_points`, :func:`ftl_kappa_batch`, :class:`ClearanceGrid`'s bounds,
:class:`TankDistance`), on random states of the reference tank, the other tanks and tanks with
random obstacles of every kind.
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import numpy as np
import pytest

from aftir_rl.core import kernel as core_kernel
from aftir_rl.core.kernel.clearance import clearance_grid, compiled_distance, kernel_grid
from aftir_rl.core.robot import _bend_rotations, body_points
from aftir_rl.core.tank import load_tank
from aftir_rl.core.tank.generate import wing_tank
from aftir_rl.core.tank.loading import tank_from_mapping
from aftir_rl.core.tank.meshes import export_tank_mesh
from aftir_rl.core.tank.solids import Box, Cylinder, Sphere
from aftir_rl.envs.ftl import kernel
from aftir_rl.envs.ftl.env import ArmFTLVectorEnv
from aftir_rl.envs.ftl.state import _RAY_AXES, RAY_DISTANCES, ftl_kappa_batch
from aftir_rl.planning.ftl.model import kappa_to_angles
from tests.helpers import random_ftl_batch


def random_tank(seed):
    """The reference tank with random boxes, cylinders along each axis and spheres."""
    rng = np.random.default_rng(seed)
    base = load_tank("b737_center")
    lo, hi = np.array(base.box_min), np.array(base.box_max)
    solids = []
    for i in range(3):
        c, h = rng.uniform(lo, hi), rng.uniform(3, 25, 3)
        solids.append(Box(tuple(c - h), tuple(c + h), f"box{i}"))
    for axis in range(3):
        p0 = rng.uniform(lo, hi)
        p1 = p0.copy()
        p1[axis] = rng.uniform(lo[axis], hi[axis])
        solids.append(Cylinder(tuple(p0), tuple(p1), float(rng.uniform(2, 10)), f"cyl{axis}"))
    for i in range(2):
        solids.append(Sphere(tuple(rng.uniform(lo, hi)), float(rng.uniform(2, 15)), f"s{i}"))
    return dataclasses.replace(base, obstacles=tuple(solids))


TANKS = ["b737_center", "single_cabin", "open_space_obstacles1", "random", "wing", "mesh"]


def tank_named(name):
    if name == "wing":  # ribs with rectangular, oval and round holes
        return tank_from_mapping(wing_tank(3, 5), "wing")
    if name == "mesh":  # a generated wing's solids read back from a mesh file
        pytest.importorskip("trimesh")
        folder = Path(tempfile.mkdtemp())
        export_tank_mesh(load_tank("wing:2:3"), folder / "w.stl", folder / "w.yaml")
        return load_tank(folder / "w.yaml")
    return random_tank(11) if name == "random" else load_tank(name)


def numpy_refresh(batch):
    """What FTLBatch.refresh computed in numpy: postures, samples, heading, clearances."""
    theta, phi = kappa_to_angles(ftl_kappa_batch(batch.kappa, batch.k, batch.s, batch.l))
    dis = batch.s - batch.n * batch.l
    pts = body_points(dis, theta, phi, batch.l, batch.k_samples)
    tip = pts[:, -1]
    heading = tip - pts[:, -2]
    heading /= np.maximum(np.linalg.norm(heading, axis=-1, keepdims=True), 1e-12)
    axes = np.concatenate([heading[:, None], np.broadcast_to(_RAY_AXES, (len(pts), 6, 3))], 1)
    rays = tip[:, None, None] + axes[:, :, None] * np.asarray(RAY_DISTANCES)[:, None]
    use = pts[..., 2] > batch._deep
    use[:, 0] = True
    body = batch.grid.row_min(pts, use) - batch.arm.radius
    ray = batch.grid.approx(rays.reshape(len(pts), -1, 3))
    return theta, phi, pts, heading, body, ray, use


@pytest.mark.parametrize("name", [*TANKS, "round:4:9"])
def test_sdf_is_the_tanks_signed_distance(name):
    tank = tank_named(name)
    rng = np.random.default_rng(0)
    lo, hi = np.array(tank.box_min) - 30, np.array(tank.box_max) + 30
    pts = rng.uniform(lo, hi, (8000, 3))
    pts[:2000, 2] = rng.uniform(-400, 5, 2000)  # in and around the guide tube
    pts[:1000, :2] = np.array(tank.panel.center)[:2] + rng.normal(0, tank.panel.radius, (1000, 2))
    packed = kernel_grid(tank)
    got = np.array([core_kernel.sdf(*p, packed) for p in pts])
    np.testing.assert_allclose(got, tank.distance(pts), rtol=0, atol=1e-9)
    # what grids are filled with: the same, many points at once
    np.testing.assert_allclose(compiled_distance(tank)(pts), tank.distance(pts), rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", ["b737_center", "round:4:9"])
def test_the_clearance_grid_holds_the_tanks_distance_at_its_nodes(name):
    """The nodes are filled by the compiled distance; each is the exact distance there."""
    tank = tank_named(name)
    rng = np.random.default_rng(2)
    for lo, g, shape, values in clearance_grid(tank).grids:
        idx = rng.integers(0, shape, (3000, 3))
        flat = (idx[:, 0] * shape[1] + idx[:, 1]) * shape[2] + idx[:, 2]
        np.testing.assert_allclose(values[flat], tank.distance(lo + g * idx), rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", TANKS)
def test_refresh_is_the_numpy_pipeline(name):
    tank = tank_named(name)
    rng = np.random.default_rng(1)
    batch = random_ftl_batch(tank, rng, 1500)
    batch.refresh()
    theta, phi, pts, heading, body, ray, use = numpy_refresh(batch)
    np.testing.assert_allclose(batch.theta, theta, atol=1e-12)
    np.testing.assert_allclose(batch.phi, phi, atol=1e-12)
    np.testing.assert_allclose(batch.points, pts, atol=1e-9)
    np.testing.assert_allclose(batch.heading, heading, atol=1e-9)
    np.testing.assert_allclose(batch.body_clearance, body, atol=1e-9)
    np.testing.assert_allclose(batch.ray_clearance, ray, atol=1e-9)
    # the body clearance is the exact minimum over the used samples, not a bound
    exact = tank.distance(pts)
    np.testing.assert_allclose(
        batch.body_clearance, np.where(use, exact, np.inf).min(1) - tank.arm.radius, atol=1e-9
    )
    assert 0.05 < batch.contact.mean() < 0.95  # both verdicts are exercised


def numpy_advance(kappa, k, s, action, target_mode, ks, push, limit, l):
    """What FTLBatch.step did in numpy before refreshing."""
    kappa, k = kappa.copy(), k.copy()
    rows = np.arange(len(kappa))
    lead = kappa[rows, k]
    if target_mode:
        want = action[:, :2] * limit
        norm = np.hypot(want[:, 0], want[:, 1])
        want *= np.where(norm > limit, limit / np.maximum(norm, 1e-12), 1.0)[:, None]
        steered = lead + np.clip(want - lead, -ks, ks)
    else:
        steered = lead + action[:, :2] * ks
        norm = np.hypot(steered[:, 0], steered[:, 1])
        steered *= np.where(norm > limit, limit / np.maximum(norm, 1e-12), 1.0)[:, None]
    kappa[rows, k] = steered
    s = np.clip(s + action[:, 2] * push, 0.0, kappa.shape[1] * l)
    new_k = np.minimum(np.floor(s / l).astype(np.int64), kappa.shape[1] - 1)
    grow = new_k > k
    kappa[rows[grow], new_k[grow]] = kappa[rows[grow], k[grow]]
    return kappa, new_k, s


@pytest.mark.parametrize("target_mode", [False, True])
def test_advance_is_the_numpy_step(target_mode):
    tank = load_tank("b737_center")
    rng = np.random.default_rng(2)
    batch = random_ftl_batch(tank, rng, 2000)
    action = rng.uniform(-1, 1, (2000, 3))
    action[:50] = np.sign(action[:50])  # the bounds
    args = (target_mode, 0.1, 5.0, tank.arm.theta_max, batch.l)
    want = numpy_advance(batch.kappa, batch.k, batch.s, action, *args)
    kernel.advance(action, batch.kappa, batch.k, batch.s, *args)
    for got, ref in zip((batch.kappa, batch.k, batch.s), want):
        np.testing.assert_allclose(got, ref, atol=1e-12)


def numpy_guide(guide, p, g, ids):
    """What FieldGuide.__call__ computed in numpy."""
    cell = guide._cell(p)
    table = guide._table
    own = table[ids, guide._flat(cell)].astype(np.float64)
    value = own + np.linalg.norm(p - (guide.origin + (cell + 0.5) * guide.size), axis=-1)
    c = cell[:, None, :] + guide.neighbours[None]
    ok = np.all((c >= 0) & (c < guide.shape), axis=-1)
    c = np.where(ok[..., None], c, 0)
    ok &= guide._edges_flat[:, guide._flat(cell)].T
    step = guide.origin + (c + 0.5) * guide.size - p[:, None, :]
    v = table[ids[:, None], guide._flat(c)] + np.sqrt(np.einsum("bni,bni->bn", step, step))
    v = np.where(ok, v, np.inf)
    pick = np.argmin(v, axis=1)
    rows = np.arange(len(p))
    best, way = v[rows, pick], step[rows, pick]
    value = np.minimum(value, best)
    home = np.all(cell == guide._cell(g), axis=-1) | ~np.isfinite(best)
    straight = g - p
    value = np.where(home, np.linalg.norm(straight, axis=-1), value)
    way = np.where(home[:, None], straight, way)
    norm = np.linalg.norm(way, axis=-1, keepdims=True)
    return value, np.where(norm > 1e-9, way / np.maximum(norm, 1e-12), 0.0)


def numpy_lookahead(guide, p, g, ids, hops):
    """What FieldGuide.lookahead computed in numpy."""
    cell = guide._flat(guide._cell(p))
    home = guide._flat(guide._cell(g))
    out = np.empty((len(p), len(hops), 3))
    done = 0
    for j, h in enumerate(hops):
        for _ in range(h - done):
            cell = guide._next[ids, cell].astype(np.int64)
        done = h
        c = np.stack(np.unravel_index(cell, tuple(guide.shape)), -1)
        out[:, j] = np.where((cell == home)[:, None], g, guide.origin + (c + 0.5) * guide.size)
    return out


def numpy_observation(batch):
    """What FTLBatch.observation computed in numpy (clipped as the observation space)."""
    lead = batch.kappa[np.arange(batch.b), batch.k] / batch.arm.theta_max
    parts = [
        (batch.dis / batch.s_max)[:, None],
        (batch.k / batch.n)[:, None],
        lead,
        batch.theta / batch.arm.theta_max,
        np.sin(batch.phi),
        np.cos(batch.phi),
        batch.tip / 100.0,
        batch.heading,
        np.clip(batch.body_clearance / 10.0, -1.0, 1.0)[:, None],
        np.clip(batch.ray_clearance / 50.0, -1.0, 1.0),
        batch.points[:, batch.k_samples :: batch.k_samples, 2][:, -3:] / 100.0,
    ]
    if batch.guide is not None:
        ids = batch.target_fields()
        to_go, direction = numpy_guide(batch.guide, batch.tip, batch.target, ids)
        theta, phi = kappa_to_angles(batch.kappa)
        ends = _bend_rotations(theta, np.cos(phi), np.sin(phi))
        frame = np.broadcast_to(np.eye(3), (batch.b, 3, 3)).copy()
        for j in range(int(batch.k.max(initial=0))):
            frame = np.where((j < batch.k)[:, None, None], frame @ ends[:, j], frame)
        ahead = numpy_lookahead(batch.guide, batch.tip, batch.target, ids, (3, 6))
        ahead -= batch.tip[:, None]
        ahead /= np.maximum(np.linalg.norm(ahead, axis=-1, keepdims=True), 1e-9)
        parts += [
            (np.minimum(to_go, 1000.0) / 100.0)[:, None],
            np.einsum("bji,bj->bi", frame, direction),
            np.einsum("bji,bj->bi", frame, batch.target - batch.tip) / 100.0,
            np.einsum("bji,bj->bi", frame, batch.heading),
            np.einsum("bji,bhj->bhi", frame, ahead).reshape(batch.b, -1),
        ]
    return np.clip(np.concatenate(parts, axis=1), -10, 10).astype(np.float32)


def test_guide_queries_and_observation_are_the_numpy_ones():
    """On a vector env's rows after random steps (guide on): the guide's queries, the
    lookahead, the steering frames and the whole observation vector."""
    env = ArmFTLVectorEnv(num_envs=64, bay=2, guide=True, steer="target")
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    batch = env.batch
    for step in range(40):
        action = rng.uniform(-1, 1, (64, 3)).astype(np.float32)
        action[:, 2] = np.clip(action[:, 2] + 0.6, -1, 1)
        env.step(action)
        if step % 10:
            continue
        ids = batch.target_fields()
        # tips anywhere in the tank too, not only where the arms went
        p = np.concatenate(
            [batch.tip, rng.uniform(batch.tank.box_min, batch.tank.box_max, (64, 3))]
        )
        g, both = np.concatenate([batch.target] * 2), np.concatenate([ids, ids])
        for got, ref in zip(batch.guide(p, g, both), numpy_guide(batch.guide, p, g, both)):
            np.testing.assert_allclose(got, ref, atol=1e-9)
        np.testing.assert_allclose(
            batch.guide.lookahead(p, g, both, (1, 3, 6)),
            numpy_lookahead(batch.guide, p, g, both, (1, 3, 6)),
            atol=1e-9,
        )
        np.testing.assert_allclose(batch.observation(), numpy_observation(batch), atol=2e-6)


def test_reward_is_the_formula():
    """The step reward of the kernel: progress, success, contact and the step cost."""
    rng = np.random.default_rng(4)
    a, g, prev = (rng.uniform(-50, 50, (5000, 3)) for _ in range(3))
    a[:1000] = g[:1000] + rng.normal(0, 1.5, (1000, 3))  # near the target: successes
    contact = rng.random(5000) < 0.3
    reward, d = np.empty(5000), np.empty(5000)
    kernel.goal_reward(a, g, prev, contact, 2.0, 0.02, reward, d)
    dist = np.linalg.norm(a - g, axis=1)
    success = (dist < 2.0) & ~contact
    want = 0.1 * (np.linalg.norm(prev - g, axis=1) - dist) + 10 * success - 10 * contact - 0.02
    np.testing.assert_allclose(d, dist, atol=1e-12)
    np.testing.assert_allclose(reward, want, atol=1e-12)
    assert success.sum() > 200 and (contact & (dist < 2.0)).sum() > 100


@pytest.mark.parametrize("samples", [1, 4, 10])
def test_fk_points_is_body_points(samples):
    """The compiled forward kinematics (AFTIR-Arm-v0's) against robot.body_points, straight
    sections and the bend limit included."""
    rng = np.random.default_rng(5)
    theta = rng.uniform(0, 1.6, (500, 12))
    theta[:50] = 0.0
    theta[50:100, ::2] = 1e-7  # the small-angle branch
    phi = rng.uniform(-np.pi, np.pi, (500, 12))
    dis = rng.uniform(-600, 0, 500)
    out = np.empty((500, 12 * samples + 1, 3))
    core_kernel.fk_points(dis, theta, phi, 50.0, samples, out)
    np.testing.assert_allclose(out, body_points(dis, theta, phi, 50.0, samples), atol=1e-9)
