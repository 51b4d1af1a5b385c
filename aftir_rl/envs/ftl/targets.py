"""Where ``AFTIR-ArmFTL-v0`` draws its targets: a bay, clear of surfaces, optionally biased.

:func:`draw_targets` draws uniform free targets (the compiled clearance check settles them
exactly), optionally weighted (``detour_bias``, ``failure_bias`` with :class:`FailureRates`) or
in the region's corners (``corner_bias``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core import kernel
from aftir_rl.core.errors import ConfigError, TargetError
from aftir_rl.core.kernel import KernelTank
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.tank import Tank

__all__ = ["CORNER_DEPTH", "FailureRates", "bay_region", "corner_candidates", "draw_targets"]


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
