"""Prioritised level replay over a stream of tanks: which wing the teacher's next routes are in.

PLR (Jiang, Grefenstette and Rocktäschel, *Prioritized Level Replay*, ICML 2021) trains on a
stream of generated levels, and with probability :attr:`LevelReplay.replay` revisits a level
met before instead of drawing a new one, chosen by its learning potential and by how long ago
it was last visited. Here a level is a generated wing, a visit is ``tank_episodes`` routes the
teacher labels in it (:func:`~aftir_rl.rl.route_policy.train_route_policy`), and a wing's
learning potential for a policy that imitates is the share of its last visit's teacher labels
the policy then gets wrong.

The replay distribution is PLR's: ``P = (1 − ρ)·P_S + ρ·P_C``, ``P_S ∝ (1/rank)^(1/β)`` by
score (rank 1 the highest) and ``P_C ∝ c − C_i`` (visits since wing ``i`` was last visited).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aftir_rl.core.errors import ConfigError

__all__ = ["LevelReplay"]


@dataclass
class LevelReplay:
    """PLR's choice between a new wing and one met before, and the scores it keeps.

    Args:
        replay: the probability that a visit replays a wing met before (PLR's ``p``).
        temperature: ``β`` of the rank prioritisation (smaller: the top ranks more often).
        staleness: ``ρ``, the weight of staleness against score.
        size: the most wings kept scored (the lowest scored are let go past it).
        min_levels: wings scored before any replay.

    Raises:
        ConfigError: a probability outside [0, 1], a temperature ≤ 0, or sizes below 1.

    """

    replay: float = 0.5
    temperature: float = 0.3
    staleness: float = 0.3
    size: int = 256
    min_levels: int = 16
    #: Each scored wing's ``[score, last visit]``, by generator spec.
    levels: dict[str, list[float]] = field(default_factory=dict)
    #: Visits so far (PLR's ``c``).
    visits: int = 0

    def __post_init__(self) -> None:
        if not (0.0 <= self.replay <= 1.0 and 0.0 <= self.staleness <= 1.0):
            raise ConfigError("replay and staleness are probabilities, 0 to 1")
        if not self.temperature > 0 or self.size < 1 or self.min_levels < 1:
            raise ConfigError("temperature must be > 0, size and min_levels at least 1")

    def probabilities(self) -> tuple[list[str], np.ndarray]:
        """The scored wings and the probability of replaying each."""
        names = list(self.levels)
        scores = np.array([self.levels[n][0] for n in names])
        last = np.array([self.levels[n][1] for n in names])
        rank = np.empty(len(names))
        rank[np.argsort(-scores, kind="stable")] = np.arange(1, len(names) + 1)
        by_score = (1.0 / rank) ** (1.0 / self.temperature)
        stale = self.visits - last
        by_score /= by_score.sum()
        by_age = stale / stale.sum() if stale.sum() > 0 else np.full(len(names), 1 / len(names))
        return names, (1.0 - self.staleness) * by_score + self.staleness * by_age

    def choose(self, rng: np.random.Generator) -> str | None:
        """The wing of the next visit: one met before (its spec), or None for a new one."""
        if len(self.levels) < self.min_levels or rng.random() >= self.replay:
            return None
        names, p = self.probabilities()
        return names[int(rng.choice(len(names), p=p))]

    def update(self, name: str, score: float) -> None:
        """Wing ``name`` was just visited and scored ``score``."""
        self.visits += 1
        self.levels[name] = [float(score), float(self.visits)]
        if len(self.levels) > self.size:
            del self.levels[min(self.levels, key=lambda n: self.levels[n][0])]
