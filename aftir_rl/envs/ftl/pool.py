"""A pool of generated tanks for ``AFTIR-ArmFTL-v0``: a new tank per episode, from a seed range.

``tank="wing:BAYS:FIRST-LAST"`` names the generated wing tanks of ``BAYS`` bays and seeds
``FIRST`` to ``LAST`` (:func:`~aftir_rl.core.tank.generate.wing_tank`; at most
:data:`MAX_POOL` of them). :class:`TankPool` builds them once (their grids are kept while the
env lives), draws one per episode with the env's generator, and gives the goal space that holds
every wing of its bays, so observations do not depend on which tank an episode has. The batched
vector env keeps one tank for all its rows; a pool runs in the single env, one tank per env of
``gym.make_vec(..., vectorization_mode="sync" | "async")``. ``FAMILY`` may be ``round`` for the
generator's round-holed family. ``tank="wing:BAYS:FIRST+"`` is an unbounded stream of them, and
``"mix:FIRST+"`` one of wings whose family and bays each seed draws (:class:`TankStream`): the
batched env moves its groups of rows along it, the route env its episodes; anywhere else a
stream of one family is its first :data:`STREAM_EVAL_TANKS` wings as a pool
(:func:`evaluation_tank`), which is how a run trained on a stream is evaluated.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import ConfigError
from aftir_rl.core.tank import Tank, load_tank
from aftir_rl.core.tank.generate import MAX_BAYS, MAX_SEED, MIX_BAYS, mixed_kind, wing_family_box
from aftir_rl.core.tank.loading import POOL_SPEC, STREAM_SPEC, generated_spec
from aftir_rl.envs.ftl.spec import FTLSpec

__all__ = [
    "MAX_POOL",
    "STREAM_EVAL_TANKS",
    "STREAM_KWARGS",
    "TankPool",
    "TankStream",
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


def pool_specs(tank: object) -> list[str] | None:
    """The generator specs of a pool ``FAMILY:BAYS:FIRST-LAST``, or None for a single tank.

    Raises:
        ConfigError: an empty range, or more than :data:`MAX_POOL` tanks.

    """
    match = POOL_SPEC.fullmatch(tank) if isinstance(tank, str) else None
    if match is None:
        return None
    family, bays, first, last = match[1], int(match[2]), int(match[3]), int(match[4])
    if not first <= last < first + MAX_POOL:
        raise ConfigError(
            f"tank {tank!r}: a pool names 1 to {MAX_POOL} seeds, FIRST-LAST with FIRST <= LAST"
        )
    return [f"{family}:{bays}:{seed}" for seed in range(first, last + 1)]


@dataclasses.dataclass(frozen=True)
class TankStream:
    """An unbounded stream of generated wings: ``FAMILY:BAYS:FIRST+`` or ``mix:FIRST+``.

    Wing ``k`` of the stream (0 first) is the generated tank of seed ``FIRST + k``: of the
    stream's family and bays, or for ``mix`` of the family and bays that seed draws
    (:func:`~aftir_rl.core.tank.generate.mixed_kind`: ``wing`` or ``round``, 2 to 5 bays).
    """

    #: The first wing's seed.
    first: int
    #: The family (``wing``, ``round``), or None for a mixed stream.
    family: str | None = "wing"
    #: The bays of every wing, or None for a mixed stream.
    bays: int | None = 3

    @property
    def text(self) -> str:
        """The spec that names the stream."""
        if self.family is None:
            return f"mix:{self.first}+"
        return f"{self.family}:{self.bays}:{self.first}+"

    @property
    def max_bays(self) -> int:
        """The most bays a wing of the stream has (what its goal space must hold)."""
        return self.bays if self.bays is not None else MIX_BAYS[1]

    def spec_at(self, k: int) -> str:
        """The generator spec of wing ``k``.

        Raises:
            ConfigError: the stream runs past the generator's last seed.

        """
        seed = self.first + int(k)
        if seed > MAX_SEED:
            raise ConfigError(f"the stream {self.text} ran past seed {MAX_SEED:,}")
        family, bays = (self.family, self.bays) if self.family else mixed_kind(seed)
        return f"{family}:{bays}:{seed}"


def stream_spec(tank: object) -> TankStream | None:
    """The stream ``FAMILY:BAYS:FIRST+`` or ``mix:FIRST+`` names, or None for anything else.

    A stream is every generated wing from seed ``FIRST`` on, each used once
    (:class:`~aftir_rl.envs.ftl.pool_vector.ArmFTLPoolVectorEnv`,
    :class:`~aftir_rl.envs.ftl.route_env.ArmRouteEnv`).

    Raises:
        ConfigError: ``BAYS`` or ``FIRST`` outside what the generator draws.

    """
    match = STREAM_SPEC.fullmatch(tank) if isinstance(tank, str) else None
    if match is None:
        return None
    first = int(match[3])
    bays = None if match[2] is None else int(match[2])
    if (bays is not None and not 1 <= bays <= MAX_BAYS) or first > MAX_SEED:
        raise ConfigError(
            f"tank {tank!r}: a stream is FAMILY:BAYS:FIRST+ with 1 to {MAX_BAYS} bays, or "
            f"mix:FIRST+, with a first seed up to {MAX_SEED:,}"
        )
    return TankStream(first, match[1], bays)


def evaluation_tank(tank: object) -> object:
    """The tank that evaluates a run trained on ``tank``: a stream's first wings as a pool.

    :data:`STREAM_EVAL_TANKS` of them, fixed whatever the run met; any other tank as it is.

    Raises:
        ConfigError: a mixed stream (a pool holds one family and one count of bays).

    """
    stream = stream_spec(tank)
    if stream is None:
        return tank
    if stream.family is None:
        raise ConfigError(
            f"tank {tank!r}: a mixed stream is evaluated in the tanks you name (--tank), "
            "not as a pool"
        )
    last = stream.first + STREAM_EVAL_TANKS - 1
    return f"{stream.family}:{stream.bays}:{stream.first}-{last}"


class TankPool:
    """The tanks of a pool, built once; the one of each episode is drawn from them."""

    def __init__(self, specs: list[str], bays: int | None = None) -> None:
        """``bays``: the most bays the goal space holds (a stream's); default the specs' most."""
        #: The pool's tanks, in seed order (kept alive: their grids are cached per tank).
        self.tanks: list[Tank] = [load_tank(s) for s in specs]
        self.names = specs
        most = max(generated_spec(s)[0] for s in specs)  # type: ignore[index]
        lo, hi = wing_family_box(max(most, bays or 0))
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
