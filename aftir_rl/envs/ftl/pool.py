"""A pool of generated tanks for ``AFTIR-ArmFTL-v0``: a new tank per episode, from a seed range.

``tank="wing:BAYS:FIRST-LAST"`` names the generated wing tanks of ``BAYS`` bays and seeds
``FIRST`` to ``LAST`` (:func:`~aftir_rl.core.tank.generate.wing_tank`; at most
:data:`MAX_POOL` of them). :class:`TankPool` builds them once (their grids are kept while the
env lives), draws one per episode with the env's generator, and gives the goal space that holds
every wing of its bays, so observations do not depend on which tank an episode has. The batched
vector env keeps one tank for all its rows; a pool runs in the single env, one tank per env of
``gym.make_vec(..., vectorization_mode="sync" | "async")``. ``tank="wing:BAYS:FIRST+"`` is an
unbounded stream of them (:func:`stream_spec`): the batched env moves its groups of rows along
it; anywhere else it is its first :data:`STREAM_EVAL_TANKS` wings as a pool
(:func:`evaluation_tank`), which is how a run trained on a stream is evaluated.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import ConfigError
from aftir_rl.core.tank import Tank, load_tank
from aftir_rl.core.tank.generate import MAX_BAYS, MAX_SEED, wing_family_box
from aftir_rl.core.tank.loading import STREAM_SPEC, generated_spec
from aftir_rl.envs.ftl.spec import FTLSpec

__all__ = [
    "MAX_POOL",
    "STREAM_EVAL_TANKS",
    "STREAM_KWARGS",
    "TankPool",
    "evaluation_tank",
    "pool_specs",
    "stream_spec",
]

#: Most tanks in one pool.
MAX_POOL = 64
#: A stream's options (of the batched env, not of the tank's episodes): evaluations drop them.
STREAM_KWARGS = ("tanks_at_once", "tank_episodes")
#: Tanks of a stream's evaluation pool: its first wings, fixed whatever the run met.
STREAM_EVAL_TANKS = 16
_POOL = re.compile(r"wing:([1-9][0-9]?):([0-9]{1,10})-([0-9]{1,10})")


def pool_specs(tank: object) -> list[str] | None:
    """The generator specs of a pool ``wing:BAYS:FIRST-LAST``, or None for a single tank.

    Raises:
        ConfigError: an empty range, or more than :data:`MAX_POOL` tanks.

    """
    match = _POOL.fullmatch(tank) if isinstance(tank, str) else None
    if match is None:
        return None
    bays, first, last = int(match[1]), int(match[2]), int(match[3])
    if not first <= last < first + MAX_POOL:
        raise ConfigError(
            f"tank {tank!r}: a pool names 1 to {MAX_POOL} seeds, FIRST-LAST with FIRST <= LAST"
        )
    return [f"wing:{bays}:{seed}" for seed in range(first, last + 1)]


def stream_spec(tank: object) -> tuple[int, int] | None:
    """``(bays, first seed)`` of a stream ``wing:BAYS:FIRST+``, or None for anything else.

    A stream is every generated wing of ``BAYS`` bays from seed ``FIRST`` on, each used once
    (:class:`~aftir_rl.envs.ftl.pool_vector.ArmFTLPoolVectorEnv`).

    Raises:
        ConfigError: ``BAYS`` or ``FIRST`` outside what the generator draws.

    """
    match = STREAM_SPEC.fullmatch(tank) if isinstance(tank, str) else None
    if match is None:
        return None
    bays, first = int(match[1]), int(match[2])
    if not 1 <= bays <= MAX_BAYS or first > MAX_SEED:
        raise ConfigError(
            f"tank {tank!r}: a stream is wing:BAYS:FIRST+ with 1 to {MAX_BAYS} bays and a first "
            f"seed up to {MAX_SEED:,}"
        )
    return bays, first


def evaluation_tank(tank: object) -> object:
    """The tank that evaluates a run trained on ``tank``: a stream's first wings as a pool.

    :data:`STREAM_EVAL_TANKS` of them, fixed whatever the run met; any other tank as it is.
    """
    stream = stream_spec(tank)
    if stream is None:
        return tank
    bays, first = stream
    return f"wing:{bays}:{first}-{first + STREAM_EVAL_TANKS - 1}"


class TankPool:
    """The tanks of a pool, built once; the one of each episode is drawn from them."""

    def __init__(self, specs: list[str]) -> None:
        #: The pool's tanks, in seed order (kept alive: their grids are cached per tank).
        self.tanks: list[Tank] = [load_tank(s) for s in specs]
        self.names = specs
        bays = {generated_spec(s)[0] for s in specs}  # type: ignore[index]
        lo, hi = wing_family_box(max(bays))
        #: The goal space's corners [cm]: the box of every wing of these bays, grown by 1 m (the
        #: same for every pool and stream of them, whichever wings it holds).
        self.goal_bounds: tuple[NDArray[np.float64], NDArray[np.float64]] = (lo - 100.0, hi + 100.0)

    def __len__(self) -> int:
        return len(self.tanks)

    def spec_for(self, spec: FTLSpec, index: int) -> FTLSpec:
        """``spec`` with the pool's tank ``index``."""
        return dataclasses.replace(
            spec, task=dataclasses.replace(spec.task, tank=self.tanks[index])
        )

    def index(self, tank: object) -> int:
        """The index of ``tank``: an index into the pool, or one of its specs.

        Raises:
            ConfigError: neither.

        """
        if isinstance(tank, (int, np.integer)) and not isinstance(tank, bool):
            if 0 <= tank < len(self.tanks):
                return int(tank)
        elif tank in self.names:
            return self.names.index(str(tank))
        raise ConfigError(
            f"tank {str(tank)[:60]!r} is not in the pool: an index 0..{len(self) - 1} or one of "
            f"{self.names[0]}..{self.names[-1]}"
        )

    def draw(self, rng: np.random.Generator) -> int:
        """The index of an episode's tank."""
        return int(rng.integers(len(self.tanks)))
