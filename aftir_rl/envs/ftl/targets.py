"""Where ``AFTIR-ArmFTL-v0`` draws its targets: a bay, clear of surfaces, optionally biased.

:class:`TargetSampler`, built from the task's ``bay`` and ``target`` and the
:class:`TrainingSpec`, is the part of an env that picks each episode's target and owns the
training-only biases and the failure rates they learn. :func:`draw_targets` draws uniform free
targets (the compiled clearance check settles them exactly), optionally weighted
(``detour_bias``, ``failure_bias`` with :class:`FailureRates`) or in the region's corners
(``corner_bias``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core import kernel
from aftir_rl.core.errors import ConfigError, TargetError
from aftir_rl.core.kernel import KernelTank
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.tank import Tank
from aftir_rl.envs.ftl.fields import raster_detour_table

if TYPE_CHECKING:
    from aftir_rl.envs.ftl.state import FTLBatch, TaskSpec

__all__ = [
    "CORNER_DEPTH",
    "FailureRates",
    "TargetSampler",
    "TrainingSpec",
    "bay_region",
    "corner_candidates",
    "draw_targets",
]


def _number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


@dataclasses.dataclass(frozen=True)
class TrainingSpec:
    """Training-only options: how targets are drawn and how strictly they are judged.

    Evaluations drop them (:data:`~aftir_rl.envs.ftl.spec.TRAINING_ONLY_KWARGS`). ``slack`` is
    read by the envs (it tightens the margin and the tolerance); the rest by
    :class:`TargetSampler`.
    """

    target_clearance: float = 10.0
    detour_bias: float = 0.0
    corner_bias: float = 0.0
    failure_bias: float = 0.0
    slack: float = 0.0

    def __post_init__(self) -> None:
        if not (_number(self.target_clearance) and 0 <= self.target_clearance < 100):
            raise ConfigError(
                f"target_clearance must be in [0, 100) cm, got {self.target_clearance!r}"
            )
        for name in ("detour_bias", "corner_bias", "failure_bias"):
            value = getattr(self, name)
            if not (_number(value) and 0 <= value <= 1):
                raise ConfigError(f"{name} must be in [0, 1], got {value!r}")
        for name in ("corner_bias", "failure_bias"):
            if getattr(self, name) > 0 and self.detour_bias > 0:
                raise ConfigError(f"give detour_bias or {name}, not both")


class TargetSampler:
    """Each episode's target: ``task.target`` if set, else drawn by the training spec.

    Targets are drawn in ``task.bay`` (the whole tank if None), ``target_clearance`` from every
    surface and 20 cm from the start (:func:`draw_targets`), with the spec's ``detour_bias``,
    ``corner_bias`` or ``failure_bias``. With ``failure_bias`` the sampler keeps
    :attr:`failures`, which :meth:`record` feeds with the ended episodes. A default
    :class:`TrainingSpec` draws uniformly, as evaluations do.

    Raises:
        ConfigError: a bias that needs the tank's raster in a tank without one.
        TargetError: ``task.target`` is not a free point of the tank
            (:meth:`~aftir_rl.envs.ftl.state.FTLBatch.check_target`).

    """

    def __init__(self, batch: FTLBatch, task: TaskSpec, training: TrainingSpec) -> None:
        self.tank = tank = batch.tank
        if (training.detour_bias > 0 or training.failure_bias > 0) and tank.cell_size is None:
            raise ConfigError("detour_bias and failure_bias need a tank with a raster (cell_size)")
        self.spec = training
        #: The corners [cm] of the region targets are drawn in.
        self.region = bay_region(tank, task.bay)
        #: Where the tip starts [cm]; targets keep 20 cm from it.
        self.start_tip = np.array([0.0, 0.0, float(task.start_height)])
        #: The target of every episode, or None (drawn).
        self.fixed_target = None if task.target is None else batch.check_target(task.target)
        #: The failure rates ``failure_bias`` draws by (None without it).
        self.failures = FailureRates(tank.raster.n_cells) if training.failure_bias > 0 else None

    def draw(self, rngs: Sequence[np.random.Generator]) -> NDArray[np.float64]:
        """One target per generator ``(len(rngs), 3)`` [cm] (the fixed one, if set)."""
        if self.fixed_target is not None:
            return np.repeat(self.fixed_target[None], len(rngs), axis=0)
        spec = self.spec
        weight: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None
        biased = 0.0
        if self.failures is not None:
            biased, weight = spec.failure_bias, self._failure_weight
        elif spec.detour_bias > 0:
            biased, weight = spec.detour_bias, self._detour_weight
        return draw_targets(
            rngs,
            self.tank,
            self.region,
            spec.target_clearance,
            self.start_tip,
            biased,
            weight,
            spec.corner_bias,
        )

    def record(self, targets: NDArray[np.float64], success: ArrayLike) -> None:
        """Give ended episodes (their targets and successes) to :attr:`failures`, if kept."""
        if self.failures is not None and len(targets):
            self.failures.record(self.tank.raster.cell_indices(targets), success)

    def _failure_weight(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`FailureRates.weight` of the points' raster cells."""
        assert self.failures is not None
        return self.failures.weight(self.tank.raster.cell_indices(points))

    def _detour_weight(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(1 + e) / (1 + e_max)``: ``e`` the raster detour [cells] from the start's cell."""
        raster = self.tank.raster
        row = raster_detour_table(self.tank)[raster.cell_indices(self.start_tip)]
        return (1.0 + row[raster.cell_indices(points)]) / (1.0 + row.max())


def bay_region(tank: Tank, bay: int | None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Corners [cm] of the tank's box, or of bay ``bay`` (:meth:`Tank.bay`: between baffles)."""
    if bay is None:
        return np.array(tank.box_min, float), np.array(tank.box_max, float)
    return tank.bay(bay)


def draw_targets(
    rngs: Sequence[np.random.Generator],
    tank: Tank,
    region: tuple[NDArray[np.float64], NDArray[np.float64]],
    clearance: float,
    start: NDArray[np.float64],
    biased: float = 0.0,
    weight: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None,
    corners: float = 0.0,
) -> NDArray[np.float64]:
    """One target per generator: uniform in ``region``, ``clearance`` [cm] from every surface.

    Each generator draws batches of 64 uniform candidates until one is at least ``clearance``
    from every surface and 20 cm from ``start``; its first such candidate is its target (the
    clearance grid settles most candidates, the rest are computed exactly: the verdicts are the
    exact ones, :func:`~aftir_rl.core.kernel.usable`). Shape ``(len(rngs), 3)``.

    With ``biased > 0`` each generator first draws whether its target is biased (probability
    ``biased``); a biased one keeps each free candidate with probability ``weight(candidate)``
    (points ``(..., 3)`` → values in ``[0, 1]``), so targets are drawn with density proportional to
    ``weight``. ``biased = 0`` draws nothing more: the targets are the same as without it.

    With ``corners > 0`` each generator then draws whether its target lies in a corner of
    ``region`` (probability ``corners``): then its candidates are uniform in the cubes of side
    :data:`CORNER_DEPTH` that start ``clearance`` inward from the region's eight corners (a
    corner drawn per candidate), where an arm must bend most with walls on three sides. The
    same checks apply (and a biased generator's weighting, in a corner too).
    """
    lo, hi = region
    start = np.ascontiguousarray(start, dtype=np.float64)
    packed = kernel_grid(tank)
    out = np.empty((len(rngs), 3))
    todo = np.arange(len(rngs))
    if biased > 0 and weight is None:
        raise ConfigError("draw_targets: biased > 0 needs a weight function")
    want = np.array([biased > 0 and rng.random() < biased for rng in rngs], dtype=bool)
    corner = np.zeros(len(rngs), dtype=bool)
    if corners > 0:
        corner[:] = [rng.random() < corners for rng in rngs]
    for _ in range(200):
        if not len(todo):
            return out
        cand = np.stack(
            [
                corner_candidates(rngs[int(i)], lo, hi, clearance)
                if corner[i]
                else rngs[int(i)].uniform(lo, hi, (64, 3))
                for i in todo
            ]
        )
        ok = _verdicts(
            cand, [rngs[int(i)] for i in todo], want[todo], weight, clearance, start, packed
        )
        found = ok.any(1)
        rows = np.flatnonzero(found)
        out[todo[rows]] = cand[rows, ok[rows].argmax(1)]
        todo = todo[~found]
    if len(todo):
        raise TargetError(f"no free point {clearance:g} cm from every surface in the target region")
    return out


def _verdicts(
    cand: NDArray[np.float64],
    rngs: Sequence[np.random.Generator],
    want: NDArray[np.bool_],
    weight: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None,
    clearance: float,
    start: NDArray[np.float64],
    packed: KernelTank,
) -> NDArray[np.bool_]:
    """Which candidates ``(R, 64, 3)`` each row may take (its own generator, biased or not).

    Clear of the surfaces and 20 cm from the start; an unbiased row is checked up to its first
    such candidate, a biased one (``want``) on every candidate, then kept by its weight.
    """
    ok = kernel.usable(cand, float(clearance), start, 20.0, packed, True)
    if want.any():
        assert weight is not None
        rows = np.flatnonzero(want)
        keep = np.stack([rngs[int(r)].random(64) for r in rows]) < weight(cand[rows])
        ok[rows] = kernel.usable(cand[rows], float(clearance), start, 20.0, packed) & keep
    return ok


#: Side [cm] of the cubes in the corners of a target region that ``corners`` draws from
#: (:func:`draw_targets`).
CORNER_DEPTH = 15.0


def corner_candidates(
    rng: np.random.Generator, lo: NDArray[np.float64], hi: NDArray[np.float64], clearance: float
) -> NDArray[np.float64]:
    """64 points ``(64, 3)``, each in the cube ``clearance`` inward from a random corner.

    Kept inside the region (a region narrower than the cubes gets points on its faces, which the
    clearance check rejects).
    """
    high = rng.integers(0, 2, (64, 3)).astype(bool)
    depth = clearance + rng.uniform(0.0, CORNER_DEPTH, (64, 3))
    return np.minimum(np.maximum(np.where(high, hi - depth, lo + depth), lo), hi)


class FailureRates:
    """Per raster cell of a tank, a running failure rate of the episodes aimed at it.

    Each ended episode moves its target cell's rate by ``rate`` towards 1 (not a success) or 0
    (a success). :meth:`weight` turns the rates into the acceptance probabilities with which
    ``failure_bias`` draws targets: cells never aimed at count as hard (weight 1), the others
    in proportion to their rate against the hardest seen (at least ``floor`` of it), so targets
    come up more often where the policy fails more, wherever that is.
    """

    def __init__(self, n_cells: int, rate: float = 0.02, floor: float = 0.05) -> None:
        self.rate, self.floor = float(rate), float(floor)
        self.fail = np.ones(n_cells)
        self.seen = np.zeros(n_cells, dtype=bool)
        #: Episodes recorded.
        self.count = 0

    def record(self, cells: ArrayLike, success: ArrayLike) -> None:
        """Record ended episodes: their target cells and whether each was a success."""
        for c, ok in zip(np.asarray(cells).tolist(), np.asarray(success).tolist()):
            self.fail[c] += self.rate * (float(not ok) - self.fail[c])
            self.seen[c] = True
            self.count += 1

    def weight(self, cells: ArrayLike) -> NDArray[np.float64]:
        """Acceptance probabilities in ``[floor, 1]`` of targets in ``cells``."""
        c = np.asarray(cells)
        hardest = max(float(self.fail[self.seen].max()) if self.seen.any() else 1.0, 1e-9)
        w = np.maximum(self.fail[c] / hardest, self.floor)
        return np.where(self.seen[c], np.minimum(w, 1.0), 1.0)
