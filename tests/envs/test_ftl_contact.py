"""The contact rule of AFTIR-ArmFTL-v0 reads the whole backbone, not only its samples 5 cm apart.

Checked against the backbone sampled every 0.25 cm (exact signed distance) and python-fcl's
capsules, on arms drawn at random whose samples all keep the margin.
"""

from __future__ import annotations

import numpy as np
import pytest

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.kernel import fk_points
from aftir_rl.core.kernel.sections import min_clearance
from aftir_rl.core.kernel.surface import FINEST
from aftir_rl.core.robot import Posture
from aftir_rl.core.tank import load_tank
from aftir_rl.envs.ftl.spec import TaskSpec
from aftir_rl.envs.ftl.state import FTLBatch


def _near_arms(batch, seed):
    """Random routes and deployments; the rows whose samples keep the margin by < 2.6 cm."""
    rng = np.random.default_rng(seed)
    b, n, limit = batch.b, batch.n, batch.arm.theta_max
    angle = rng.uniform(-np.pi, np.pi, (b, n))
    size = rng.uniform(0, 1, (b, n)) * limit * rng.uniform(0, 0.6, (b, 1))
    batch.kappa = np.stack([size * np.cos(angle), size * np.sin(angle)], -1)
    batch.k = np.full(b, n - 1, dtype=np.int64)
    batch.s = rng.uniform(10, n * batch.l, b)
    batch.refresh()
    clear = batch.body_clearance
    return np.flatnonzero((clear >= batch.margin) & (clear < batch.margin + 2.6))


def _dense_clearance(batch, rows, per_section=200):
    """The surface clearance of the backbone sampled every ``l / per_section`` (exact distance)."""
    n = batch.n
    pts = np.empty((len(rows), n * per_section + 1, 3))
    fk_points((batch.s - n * batch.l)[rows], batch.theta[rows], batch.phi[rows], batch.l,
              per_section, pts)  # fmt: skip
    out = np.empty(len(rows))
    for i, p in enumerate(pts):
        used = np.ones(len(p), dtype=bool)
        used[1:] = p[1:, 2] > batch._deep  # the guide below, as the env reads it
        out[i] = min_clearance(np.ascontiguousarray(p[used]), batch._kernel_tank)
    return out - batch.arm.radius


@pytest.mark.parametrize("name", ["b737_center", pytest.param("wing:3:5", marks=pytest.mark.slow)])
def test_contact_between_samples_is_found(name):
    tank = load_tank(name)
    batch = FTLBatch(TaskSpec(tank=tank, n_sections=12), 5000)
    scene = CollisionScene(tank)
    spacing = batch.l / 200
    dips = 0
    for seed in range(40):
        rows = _near_arms(batch, seed)
        dense = _dense_clearance(batch, rows)
        contact = batch.contact[rows]
        # a dip below the margin between samples is a contact ...
        assert not np.any((dense < batch.margin - FINEST) & ~contact)
        # ... and a contact is one, up to the halving's and this check's own resolution
        assert np.all(dense[contact] < batch.margin + FINEST + spacing**2)
        dips += int(np.sum(contact))
        for i in rows[~contact][:40]:  # python-fcl's capsules agree with every contact-free arm
            posture = Posture(batch.s[i] - batch.n * batch.l, batch.theta[i], batch.phi[i])
            assert scene.clearance(posture) > batch.margin - 0.11  # capsules: sagitta + 0.01
    if name == "b737_center":
        assert dips >= 1  # the samples alone called these arms contact-free
