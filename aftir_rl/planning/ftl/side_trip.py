"""Side trips of an inspection tour: from one target's posture to a nearby target and back.

At a target the arm can reach another one without pushing: the module and the first sections
stay, the last 2 to 4 sections bend along a straight line in joint space to a posture whose tip
is on the other target, and the arm comes back the same way. A trip is not follow-the-leader
(the bending sections sweep sideways), so one is kept only where its dense move keeps the
margin. Bending at 0.2 rad/s takes seconds where pushing a section's length out and back at
5 cm/s takes tens of them, so :func:`choose_side_trips` makes a trip wherever it is quicker
than the legs that visiting the target by its route would add to the tour.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import PlanningError
from aftir_rl.core.robot import ArmSpec, angles_to_kappa
from aftir_rl.core.tank import Tank
from aftir_rl.planning.ftl.closing import close_batch
from aftir_rl.planning.ftl.model import kappa_to_angles
from aftir_rl.planning.ftl.plan import postures_clearance
from aftir_rl.planning.timing import TimedMotion, time_motion

__all__ = [
    "FREE_SECTIONS",
    "REACH",
    "SideTrip",
    "choose_side_trips",
    "host_postures",
    "side_trips",
    "straight_move",
]

#: How many of the last sections a trip may bend (each count is tried).
FREE_SECTIONS = (2, 3, 4)
#: Targets farther apart than this many section lengths get no trip.
REACH = 2.5
#: Largest move [cm] of any backbone point between two entries of a straight move.
STEP_CM = 0.5

Postures = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


@dataclass(frozen=True)
class SideTrip:
    """A move from target ``host``'s posture to one whose tip is on target ``target``.

    ``path``: ``dis (T,)``, ``theta``, ``phi (T, N)`` from the host's posture on; ``timed``: its
    time-optimal schedule (from rest to rest); the way back is the same path reversed.
    """

    host: int
    target: int
    path: Postures
    timed: TimedMotion
    clearance_cm: float

    @property
    def duration(self) -> float:
        """One way [s]."""
        return self.timed.duration


def straight_move(a: NDArray[np.float64], b: NDArray[np.float64], arm: ArmSpec) -> Postures:
    """A straight line in joint space from ``a`` to ``b`` (``(dis, κ...)`` vectors), dense.

    No backbone point moves more than :data:`STEP_CM` between entries: a section's bending
    change δ turns everything beyond its base by at most δ, which moves a point at most δ times
    its arc distance from that base.
    """
    n = (len(a) - 1) // 2
    bends = np.linalg.norm((b[1:] - a[1:]).reshape(n, 2), axis=1)
    reach = abs(a[0] - b[0]) + float(bends @ (arm.section_length * np.arange(n, 0, -1)))
    u = np.linspace(0.0, 1.0, max(2, int(np.ceil(reach / STEP_CM)) + 1))[:, None]
    q = a + u * (b - a)  # joints that do not move stay exactly where they are
    q[-1] = b
    theta, phi = kappa_to_angles(q[:, 1:].reshape(len(q), n, 2))
    return q[:, 0].copy(), theta, phi


def side_trips(
    tank: Tank, postures: dict[int, NDArray[np.float64]], targets: NDArray[np.float64],
    margin: float,
) -> dict[tuple[int, int], SideTrip]:  # fmt: skip
    """The quickest trip of every pair ``(host, target)`` that has one.

    ``postures``: each host's joint vector ``(dis, κ...)`` at its target (where it arrives by
    its route). For each target, every host within :data:`REACH` sections bends its last
    :data:`FREE_SECTIONS` by damped least squares from its own posture (the least change); of
    the moves that keep ``margin`` (checked densely), the one with the least bending is timed
    (none where a cable would leave its travel).
    """
    arm = tank.arm
    l, found = arm.section_length, {}
    for b, target in enumerate(targets):
        hosts = [a for a in postures if a != b and np.linalg.norm(targets[a] - target) <= REACH * l]
        if b not in postures or not hosts:
            continue
        q = np.array([postures[a] for a in hosts])
        n = (q.shape[1] - 1) // 2
        best: dict[int, tuple[float, Postures, float]] = {}
        for free in FREE_SECTIONS:
            closed = close_batch(q[:, 0], q[:, 1:].reshape(-1, n, 2), target, l, arm.theta_max,
                                 free=min(free, n), iterations=60, lead_range=None)  # fmt: skip
            for a, qa, got in zip(hosts, q, closed):
                if got is None:
                    continue
                qb = np.concatenate([[got[0]], got[1].ravel()])
                bend = float(np.abs(qb - qa).max())  # the bending rate is what takes the time
                if a not in best or bend < best[a][0]:
                    path = straight_move(qa, qb, arm)
                    clearance = postures_clearance(tank, *path)
                    if clearance >= margin and np.abs(path[1]).max() <= arm.theta_max + 1e-9:
                        best[a] = (bend, path, clearance)
        for a, (_, path, clearance) in best.items():
            try:
                timed = time_motion(*path, arm.section_length, arm.limits)
            except PlanningError:  # a cable would leave its travel: no trip
                continue
            found[a, b] = SideTrip(a, b, path, timed, clearance)
    return found


def choose_side_trips(
    costs: NDArray[np.float64], nodes: list[int], order: list[int],
    trips: dict[tuple[int, int], SideTrip],
) -> tuple[list[int], dict[int, SideTrip]]:  # fmt: skip
    """Which targets the tour visits by a side trip, and the order of the others.

    ``costs``: leg durations between the panel (node 0) and targets ``nodes`` (node ``i + 1``);
    ``order``: the tour's order of all targets. Greedily, the target whose trip there and back
    saves the most against the legs around it in the current order (from a host still visited
    by its route, and not itself a host) leaves the order, until no trip saves time.
    """
    node = {j: i + 1 for i, j in enumerate(nodes)}
    seq: list[int] = [0, *(node[j] for j in order), 0]  # node numbers; 0: the panel
    chosen: dict[int, SideTrip] = {}
    while True:
        best: tuple[float, int, SideTrip] | None = None
        hosts = {node[trip.host] for trip in chosen.values()}
        for pos in range(1, len(seq) - 1):
            before, here, after = seq[pos - 1], seq[pos], seq[pos + 1]
            if here in hosts:
                continue
            legs = float(costs[before, here] + costs[here, after] - costs[before, after])
            for h in seq[1:-1]:
                trip = trips.get((nodes[h - 1], nodes[here - 1]))
                if trip is not None and (best is None or legs - 2 * trip.duration > best[0]):
                    best = (legs - 2 * trip.duration, pos, trip)
        if best is None or best[0] <= 0:
            return [nodes[k - 1] for k in seq[1:-1]], chosen
        chosen[best[2].target] = best[2]
        del seq[best[1]]


def host_postures(motions: dict[int, Postures]) -> dict[int, NDArray[np.float64]]:
    """Each target's joint vector ``(dis, κ...)`` at the last entry of its deployment."""
    return {
        j: np.concatenate([[dis[-1]], angles_to_kappa(theta[-1], phi[-1]).ravel()])
        for j, (dis, theta, phi) in motions.items()
    }
