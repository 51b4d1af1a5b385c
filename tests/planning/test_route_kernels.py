"""The planner's compiled kernels against independent answers, on random draws (seeded).

Sections against the numpy forward kinematics and exact clearance; closings by the numpy tip;
the guide's Dijkstra against scipy's; its query, the FTL deviation and the shape fit against
numpy transcriptions of their definitions; the motion check against python-fcl-free brute force.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from aftir_rl.core.collision import point_clearance
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.kernel.deployment import fit_shape, traced_deviation
from aftir_rl.core.kernel.sections import (
    close,
    extend,
    joint_tip_jacobian,
    postures_min_clearance,
)
from aftir_rl.core.robot import body_points, kappa_to_angles, tip_jacobian, tip_position
from aftir_rl.core.tank import load_tank
from aftir_rl.planning.ftl.guide import NEIGHBOURS, GuideField, shifted
from aftir_rl.planning.ftl.model import clip_kappa

TANKS = ["b737_center", "wing:3:4"]


@pytest.fixture(scope="module", params=TANKS)
def tank(request):
    return load_tank(request.param)


def _random_frames(rng, n):
    """Random rotations (QR of Gaussian matrices, det +1) and positions in the reference box."""
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q = q * np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]
    q[np.linalg.det(q) < 0, :, 0] *= -1
    return q


def test_extend_matches_numpy_sections_and_exact_clearance(tank):
    rng = np.random.default_rng(3)
    arm, b, k = tank.arm, 40, 10
    changes = rng.uniform(-0.75, 0.75, (9, 2))
    rot = _random_frames(rng, b)
    assert np.allclose(rot @ np.swapaxes(rot, 1, 2), np.eye(3)) and np.allclose(
        np.linalg.det(rot), 1
    )
    pos = rng.uniform(tank.box_min, tank.box_max, (b, 3))
    last = rng.uniform(-1.0, 1.0, (b, 2))
    allowed = rng.random(b) < 0.9
    n = b * len(changes)
    out = [np.empty((n, 2)), np.empty((n, 3, 3)), np.empty((n, 3)), np.empty(n), np.empty(n, bool)]
    need, margin = arm.radius + 2.5, 1.0
    exact_below = arm.radius + margin + 3.0
    clearance = (need, arm.radius, margin, exact_below)
    extend(rot, pos, last, allowed, changes, (arm.theta_max, arm.section_length, k), clearance,
           kernel_grid(tank), *out)  # fmt: skip
    kap, end_rot, end_pos, cost, ok = out
    rep = np.repeat(np.arange(b), len(changes))
    want_k = clip_kappa(last[rep] + np.tile(changes, (b, 1)), arm.theta_max)
    np.testing.assert_allclose(kap, want_k, atol=1e-12)
    theta, phi = kappa_to_angles(want_k)
    frac = np.arange(1, k + 1) / k
    from aftir_rl.core.robot import section_transforms

    local = section_transforms(theta[:, None] * frac, phi[:, None], arm.section_length * frac)
    pts = np.einsum("bij,bkj->bki", rot[rep], local[..., :3, 3]) + pos[rep][:, None, :]
    np.testing.assert_allclose(end_pos[ok], pts[ok, -1], atol=1e-9)  # (a miss stops early)
    np.testing.assert_allclose(end_rot, rot[rep] @ local[:, -1, :3, :3], atol=1e-9)
    exact = point_clearance(tank, pts)
    want_ok = allowed[rep] & (exact >= need).all(axis=1)
    assert np.array_equal(ok, want_ok)
    # far samples use the grid's value (within its slack): bound the cost's difference
    want_cost = np.sum(1.0 / np.maximum(exact - arm.radius - margin, 0.25), axis=1)
    slack = kernel_grid(tank).slack
    far = exact_below - arm.radius - margin - slack
    bound = k * (1.0 / far - 1.0 / (far + 2 * slack))
    assert np.all(np.abs(cost - want_cost)[ok] <= bound + 1e-9)


def test_close_puts_the_numpy_tip_on_the_target(tank):
    rng = np.random.default_rng(5)
    arm, l = tank.arm, tank.arm.section_length
    c, m = 60, 4
    kappa = rng.uniform(-0.8, 0.8, (c, m, 2))
    lead = rng.uniform(-20, 40, c)
    target = tip_position(lead[0], *kappa_to_angles(kappa[0] * 0.7), l)
    lo, hi = np.full(c, -25.0), np.full(c, 60.0)
    ok = np.zeros(c, bool)
    got_lead, got_k = lead.copy(), kappa.copy()
    close(got_lead, got_k, target, l, arm.theta_max, 3, 40, lo, hi, True, ok)
    assert ok.sum() >= c // 4  # a good share converges from random starts
    tips = tip_position(got_lead, *kappa_to_angles(got_k), l)
    assert np.all(np.linalg.norm(tips[ok] - target, axis=1) < 1e-6)
    assert np.all(np.linalg.norm(tips[~ok] - target, axis=1) >= 1e-6)
    assert np.all(np.hypot(got_k[..., 0], got_k[..., 1]) <= arm.theta_max + 1e-12)
    assert np.all((got_lead >= -25.0) & (got_lead <= 60.0))
    np.testing.assert_array_equal(got_k[:, : m - 3], kappa[:, : m - 3])  # fixed sections stay


@pytest.mark.parametrize("n", [1, 4, 13])
def test_joint_tip_jacobian_equals_numpy_and_an_analytic_column(n):
    """The compiled tip and Jacobian against numpy's (random joints, straight sections among
    them), and the dis column against its exact value: the tip moves with dis along z."""
    rng = np.random.default_rng(n)
    for _ in range(20):
        theta = rng.uniform(-1.5, 1.5, n) * (rng.random(n) > 0.3)
        x = np.concatenate([[rng.uniform(-300, 0)], theta, rng.uniform(-np.pi, np.pi, n)])
        tip, jac = np.empty(3), np.empty((3, len(x)))
        joint_tip_jacobian(x, 25.0, 1e-6, tip, jac)
        want_tip, want_jac = tip_jacobian(x, 25.0)
        np.testing.assert_allclose(tip, want_tip, atol=1e-9)
        np.testing.assert_allclose(jac, want_jac, atol=1e-6)
        np.testing.assert_allclose(jac[:, 0], [0, 0, 1], atol=1e-6)


def test_guide_dijkstra_equals_scipy(tank):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    rng = np.random.default_rng(8)
    target = rng.uniform(tank.box_min, tank.box_max)
    field = GuideField(tank, target, clearance_cost=2.0)
    shape = tuple(int(v) for v in field.shape)
    n = int(np.prod(shape))
    flat = np.arange(n).reshape(shape)
    rows, cols, weights = [], [], []
    for e, (d, w) in enumerate(zip(NEIGHBOURS, field.weights)):
        # the edge x -> x + d, usable by a free x: dist[x] <= dist[x + d] + w(x)
        ok = field.edges[e] & field.free & np.isfinite(shifted(np.zeros(shape), -d))
        x = flat[ok]
        y = x + int(np.dot(d, [shape[1] * shape[2], shape[2], 1]))
        rows.append(y)
        cols.append(x)
        weights.append(np.broadcast_to(w, shape)[ok])
    graph = coo_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(n + 1, n + 1)).tolil()  # fmt: skip
    near = np.linalg.norm(_centres(field) - target, axis=-1).reshape(-1)
    free = field.free.reshape(-1)
    seeds = np.flatnonzero(free & (near <= 1.75 * field.size))
    if len(seeds) == 0:  # GuideField's fallback: the nearest free grid points
        seeds = np.flatnonzero(free & (near <= near[free].min() + 1e-9))
    graph[n, seeds] = near[seeds]  # a source joined to each seed by its straight distance
    want = dijkstra(graph.tocsr(), indices=n)[:n]
    got = field.dist.reshape(-1)
    assert np.array_equal(np.isfinite(got), np.isfinite(want))
    np.testing.assert_allclose(got[np.isfinite(got)], want[np.isfinite(want)], atol=1e-9)


def _heapq_dijkstra(dist, free, edges, weights, shape):
    """The textbook Dijkstra in Python (``heapq`` of ``(distance, point)`` pairs, stale pairs
    skipped), over the same flat grid and edges as :func:`relax_field`."""
    import heapq

    off = [int(np.dot(d, [shape[1] * shape[2], shape[2], 1])) for d in NEIGHBOURS]
    dist = dist.copy()
    heap = [(float(d), int(x)) for x, d in enumerate(dist) if np.isfinite(d)]
    heapq.heapify(heap)
    n = len(dist)
    while heap:
        dy, y = heapq.heappop(heap)
        if dy > dist[y]:
            continue
        for e, o in enumerate(off):
            x = y - o
            if 0 <= x < n and edges[e, x] and free[x] and dy + weights[e, x] < dist[x]:
                dist[x] = dy + weights[e, x]
                heapq.heappush(heap, (dist[x], x))
    return dist


def test_guide_dijkstra_settles_as_heapq_does():
    """Fields of random targets in a tank and a wing, bit for bit those of the textbook
    Dijkstra on a ``heapq`` (the same sums in the same order), and each grid point's next step
    the first neighbour of least distance via it."""
    from aftir_rl.core.kernel.guide import descend_field, relax_field

    rng = np.random.default_rng(14)
    for name in ("b737_center", "wing:2:7"):
        tank = load_tank(name)
        for _ in range(2):
            field = GuideField(tank, rng.uniform(tank.box_min, tank.box_max), clearance_cost=2.0)
            shape, free = field.shape, field.free.reshape(-1)
            edges, table = (
                np.ascontiguousarray(field.edges.reshape(len(NEIGHBOURS), -1)),
                field.weight_table,
            )
            seeded = np.where(
                field.dist.reshape(-1) <= 1.75 * field.size, field.dist.reshape(-1), np.inf
            )
            got = seeded.copy()
            relax_field(got, free, edges, table, NEIGHBOURS, shape)
            want = _heapq_dijkstra(seeded, free, edges, table, shape)
            np.testing.assert_array_equal(got, want)
            nxt = np.empty(len(got), dtype=np.int32)
            descend_field(got, edges, table, NEIGHBOURS, shape, nxt)
            flat = np.arange(len(got)).reshape(tuple(shape))
            best, arg = np.full(len(got), np.inf), np.arange(len(got))
            for e, d in enumerate(NEIGHBOURS):
                y = shifted(flat.astype(float), -d).reshape(-1)  # x + d, inf outside
                ok = edges[e] & np.isfinite(y)
                via = np.full(len(got), np.inf)
                via[ok] = got[y[ok].astype(int)] + table[e, ok]
                better = via < best
                best[better], arg[better] = via[better], y[better].astype(int)
            arg[got < best - 1e-9] = np.flatnonzero(got < best - 1e-9)
            np.testing.assert_array_equal(nxt, arg)


def _centres(field):
    return field.origin + (np.indices(tuple(field.shape)).transpose(1, 2, 3, 0) + 0.5) * field.size


def test_guide_query_equals_its_numpy_definition(tank):
    rng = np.random.default_rng(9)
    field = GuideField(tank, rng.uniform(tank.box_min, tank.box_max))
    p = rng.uniform(np.array(tank.box_min) - 5, np.array(tank.box_max) + 5, (3000, 3))
    p[:50] = field.target + rng.normal(0, 3, (50, 3))  # near the target
    cell = np.clip(np.floor((p - field.origin) / field.size).astype(int), 0, field.shape - 1)
    centre = field.origin + (cell + 0.5) * field.size
    best = field.dist[tuple(cell.T)] + np.linalg.norm(p - centre, axis=-1)
    for e, d in enumerate(NEIGHBOURS):
        c = cell + d
        inside = np.all((c >= 0) & (c < field.shape), axis=-1)
        cc = np.where(inside[:, None], c, 0)
        joined = field.edges[e][tuple(cell.T)] & inside
        other = field.origin + (cc + 0.5) * field.size
        v = field.dist[tuple(cc.T)] + np.linalg.norm(p - other, axis=-1)
        best = np.minimum(best, np.where(joined, v, np.inf))
    near = np.linalg.norm(p - field.target, axis=-1)
    want = np.where(near < field.size, np.minimum(best, near), best)
    np.testing.assert_array_equal(field(p), want)


def test_min_clearance_of_postures_is_the_exact_minimum(tank):
    rng = np.random.default_rng(12)
    t, n = 30, tank.arm.max_sections
    dis = rng.uniform(-n * tank.arm.section_length, 0.0, t)
    theta, phi = rng.uniform(0, 1.2, (t, n)), rng.uniform(-np.pi, np.pi, (t, n))
    got = postures_min_clearance(dis, theta, phi, tank.arm.section_length, 20, kernel_grid(tank))
    want = point_clearance(tank, body_points(dis, theta, phi, tank.arm.section_length, 20)).min()
    assert got == pytest.approx(float(want), abs=1e-9)


def test_traced_deviation_equals_its_numpy_definition():
    rng = np.random.default_rng(13)
    s = np.cumsum(rng.uniform(0.2, 1.0, 120))
    tips = np.cumsum(rng.normal(0, 0.6, (120, 3)), axis=0) + [0, 0, 10]
    points = rng.normal(0, 20, (120, 41, 3))
    back = np.linspace(200, 0, 41)
    worst, total = traced_deviation(points, tips, s, back, 12, 0)
    want = []
    for t in range(120):
        for p in range(41):
            u = s[t] - back[p]
            if u <= s[0]:
                want.append(math.hypot(*points[t, p, :2]))
                continue
            centre = int(np.searchsorted(s, u))
            d = np.inf
            for w in range(-12, 13):
                a = min(max(centre + w, 0), max(t - 1, 0))
                b = min(a + 1, t)
                ab = tips[b] - tips[a]
                f = np.clip(np.dot(points[t, p] - tips[a], ab) / max(ab @ ab, 1e-12), 0, 1)
                d = min(d, float(np.linalg.norm(tips[a] + f * ab - points[t, p])))
            want.append(d)
    assert worst == pytest.approx(max(want), rel=1e-12)
    assert total == pytest.approx(sum(want), rel=1e-12)


def test_fit_shape_equals_numpy_gauss_newton():
    rng = np.random.default_rng(14)
    n, per, l = 5, 5, 50.0
    kappa = rng.uniform(-0.6, 0.6, (n, 2))
    goal = body_points(-100.0, *kappa_to_angles(kappa + rng.normal(0, 0.1, (n, 2))), l, per)
    weight = np.ones(n * per + 1)
    weight[-1] = 10.0
    got = kappa.copy()
    fit_shape(-100.0, got, 2, goal, weight, l, per, 4)
    want = kappa.copy()
    for _ in range(4):
        base = body_points(-100.0, *kappa_to_angles(want), l, per)
        err = ((goal - base) * weight[:, None]).reshape(-1)
        trial = np.repeat(want[None], 2 * (n - 2), axis=0)
        for v in range(2 * (n - 2)):
            trial[v, 2 + v // 2, v % 2] += 1e-6
        pts = body_points(-100.0, *kappa_to_angles(trial), l, per)
        jac = (((pts - base[None]) * weight[None, :, None]).reshape(len(trial), -1) / 1e-6).T
        step = np.linalg.solve(jac.T @ jac + 1e-6 * np.eye(len(trial)), jac.T @ err)
        want[2:] += step.reshape(-1, 2)
        if np.abs(step).max() < 1e-7:
            break
    np.testing.assert_allclose(got, want, atol=1e-6)  # finite differences of step 1e-6
    np.testing.assert_array_equal(got[:2], kappa[:2])


def test_guide_fields_are_kept_per_target_and_bounded():
    from aftir_rl.planning.ftl import guide

    tank = load_tank("b737_center")
    first = guide.guide_field(tank, [100.0, 90.0, 50.0])
    assert guide.guide_field(tank, [100.0, 90.0, 50.0]) is first
    assert guide.guide_field(tank, [100.0, 90.0, 50.5]) is not first
    for i in range(guide.GUIDE_CACHE_SIZE + 2):
        guide.guide_field(tank, [100.0, 90.0, 10.0 + i])
    assert len(guide._FIELDS[tank]) == guide.GUIDE_CACHE_SIZE
    assert guide.guide_field(tank, [100.0, 90.0, 50.0]) is not first  # the oldest left
    np.testing.assert_array_equal(guide.guide_field(tank, [100.0, 90.0, 50.0]).dist, first.dist)


@pytest.mark.parametrize("name", ["b737_center", "round:2:3"])
def test_the_guides_grid_edges_are_their_definition(name):
    """Filled a plane of the half-spacing grid at a time: equal to the definition, the exact
    clearance of every grid point, and an edge where both ends and its midpoint are free."""
    from aftir_rl.planning.ftl.guide import _grid_edges

    tank = load_tank(name)
    size = float(tank.raster.cell_size) / 2
    free, edges, clear = _grid_edges(tank, size)
    shape = tuple(int(n) * 2 for n in tank.raster.shape)
    centres = np.array(tank.raster.origin) + (np.indices(shape).transpose(1, 2, 3, 0) + 0.5) * size
    expected = point_clearance(tank, centres)
    np.testing.assert_allclose(clear, expected, rtol=0, atol=1e-9)
    r = tank.arm.radius
    np.testing.assert_array_equal(free, expected >= r)
    for e, d in enumerate(NEIGHBOURS):
        ends = shifted(free.astype(float), -d) == 1.0
        mid = point_clearance(tank, centres + 0.5 * size * d) >= r
        np.testing.assert_array_equal(edges[e], free & ends & mid)
