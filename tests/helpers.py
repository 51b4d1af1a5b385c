"""Helpers several test modules share (plain functions; fixtures live in conftest.py)."""

from __future__ import annotations

import numpy as np

from aftir_rl.envs.ftl.spec import TaskSpec
from aftir_rl.envs.ftl.state import FTLBatch


def ftl_batch(tank, b, **kwargs):
    """An FTL batch of ``b`` arms with the env's defaults; any keyword of :class:`TaskSpec`
    overrides one of them."""
    return FTLBatch(TaskSpec(tank=tank, **kwargs), b)


def random_ftl_batch(tank, rng, b, margin=1.0, **kwargs):
    """An FTL batch of ``b`` arms in random states, not yet refreshed.

    Routes from straight to sharply bent (each section's bend up to θ_max, most of them mild),
    in any direction, and tips anywhere along them (any deployment).
    """
    batch = ftl_batch(tank, b, margin=margin, **kwargs)
    n = batch.n
    r = rng.uniform(0, 1, (b, n)) ** 2 * tank.arm.theta_max * rng.uniform(0, 1, (b, 1))
    a = rng.uniform(-np.pi, np.pi, (b, n))
    batch.kappa = np.stack([r * np.cos(a), r * np.sin(a)], -1)
    batch.s = rng.uniform(0, batch.s_max, b)
    batch.k = np.minimum(np.floor(batch.s / batch.l).astype(np.int64), n - 1)
    return batch
