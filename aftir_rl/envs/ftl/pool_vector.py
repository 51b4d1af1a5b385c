"""A pool of tanks in the batched ``AFTIR-ArmFTL-v0``: one tank per group of rows.

:class:`ArmFTLPoolVectorEnv` splits its ``num_envs`` rows into one contiguous group per tank of
the pool ``tank="wing:BAYS:FIRST-LAST"`` (the first ``num_envs`` tanks if the pool is larger),
as equal as can be, each group an :class:`~aftir_rl.envs.ftl.env.ArmFTLVectorEnv` of its own
tank, stepped one after the other. Rows keep their tank: row ``i`` seeded ``seed + i`` draws its
targets as row ``i - start`` of its group does. The goal space holds every wing of the pool's
bays (:func:`~aftir_rl.core.tank.generate.wing_family_box`).
With a stream ``tank="wing:BAYS:FIRST+"`` (or ``"mix:FIRST+"``) the groups' tanks are the
stream's first ones, and a group whose rows have ended ``tank_episodes`` episodes moves on to
the stream's next unused wing: its running episodes end there (truncated), and its rows start
again in the new tank.
:func:`make_vector_env` is the registered vector entry point: a pool or a stream gives this env,
one tank the plain batched one.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from aftir_rl.core.errors import ConfigError, InvalidActionError, TargetError
from aftir_rl.core.tank import load_tank
from aftir_rl.envs.ftl.env import ArmFTLVectorEnv, same_step_finals
from aftir_rl.envs.ftl.pool import TankPool, pool_specs, stream_spec

__all__ = ["ArmFTLPoolVectorEnv", "make_vector_env"]

Obs = dict[str, NDArray[np.float32]]


def make_vector_env(
    num_envs: int = 1, max_episode_steps: int = 300, **kwargs: Any
) -> VectorEnv[Any, Any, Any]:
    """The batched env of ``AFTIR-ArmFTL-v0``: :class:`ArmFTLPoolVectorEnv` for a pool."""
    if pool_specs(kwargs.get("tank")) is not None or stream_spec(kwargs.get("tank")) is not None:
        return ArmFTLPoolVectorEnv(num_envs, max_episode_steps, **kwargs)
    return ArmFTLVectorEnv(num_envs, max_episode_steps, **kwargs)


class ArmFTLPoolVectorEnv(VectorEnv[Obs, NDArray[np.float32], Any]):
    """``num_envs`` arms in the tanks of a pool or a stream, one batched group of rows per tank.

    Same arguments as :class:`~aftir_rl.envs.ftl.env.ArmFTLVectorEnv`, with ``tank`` a pool or a
    stream, and for a stream ``tanks_at_once`` (groups of rows, default 8) and
    ``tank_episodes`` (episodes a group's rows end in one tank before it takes the next,
    default 256). ``reset(options={"target": ...})`` takes one target per row ``(num_envs, 3)``
    (or one for all rows, which must then be free in every tank). ``info`` holds the per-row
    arrays of the groups, and ``reset``'s ``info["tank"]`` each row's tank; ``row_tanks`` is
    each row's tank now. A seeded ``reset`` starts a stream again from its first wings.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int = 300,
        *,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
        tanks_at_once: int | None = None,
        tank_episodes: int | None = None,
        **kwargs: Any,
    ) -> None:
        if not isinstance(num_envs, int) or num_envs < 1:
            raise ConfigError("num_envs and max_episode_steps must be at least 1")
        #: The stream, or None for a pool.
        self.stream = stream_spec(kwargs.get("tank"))
        specs, self.tank_episodes = _first_tanks(
            kwargs.get("tank"), num_envs, tanks_at_once, tank_episodes
        )
        groups = min(len(specs), num_envs)
        self.pool = TankPool(specs[:groups], None if self.stream is None else self.stream.max_bays)
        self.goal_bounds = self.pool.goal_bounds  # every wing of these bays: the stream's too
        sizes = [num_envs // groups + (g < num_envs % groups) for g in range(groups)]
        #: Each group's first row, and the end: group ``g`` holds rows ``starts[g]:starts[g+1]``.
        self.starts = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self._group_args: dict[str, Any] = {
            "max_episode_steps": max_episode_steps,
            "autoreset_mode": autoreset_mode,
            "render_mode": render_mode,
            "goal_bounds": self.goal_bounds,
            **kwargs,
        }
        self.groups = [
            ArmFTLVectorEnv(size, **{**self._group_args, "tank": tank})
            for size, tank in zip(sizes, self.pool.tanks)
        ]
        first_group = self.groups[0]
        self.num_envs, self.max_episode_steps = num_envs, first_group.max_episode_steps
        self.render_mode = None
        self.autoreset_mode = first_group.autoreset_mode
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.single_action_space = first_group.single_action_space
        self.single_observation_space = first_group.single_observation_space
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        #: Each row's tank (its generator spec).
        self.row_tanks = [name for name, n in zip(self.pool.names, sizes) for _ in range(n)]
        self._episodes = np.zeros(groups, dtype=np.int64)  # a stream's, per group and tank
        #: The tanks the rows have been in since the last seeded reset (a pool's: its groups').
        self.tanks_met = groups
        self._seed: int | None = None

    def _slices(self) -> list[slice]:
        return [slice(a, b) for a, b in zip(self.starts[:-1], self.starts[1:])]

    def reset(
        self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Obs, dict[str, Any]]:
        """Reset every row; ``seed`` seeds row ``i`` with ``seed + i`` (or a list, one each)."""
        if seed is not None and not isinstance(seed, int):
            if len(seed) != self.num_envs:
                raise ConfigError(f"reset got {len(seed)} seeds for {self.num_envs} envs")
        targets = None
        if options and options.get("target") is not None:
            t = np.asarray(options["target"], dtype=np.float64)
            targets = t.reshape(-1, 3) if t.size % 3 == 0 else t
            if targets.ndim != 2 or len(targets) not in (1, self.num_envs):
                raise TargetError(f"target must be (3,) or ({self.num_envs}, 3), got {t.shape}")
            targets = np.broadcast_to(targets, (self.num_envs, 3))
        if self.stream is not None and seed is not None:
            self._restart_stream()
            self._seed = seed if isinstance(seed, int) else int(seed[0])
        outs = []
        for group, rows in zip(self.groups, self._slices()):
            own = None if seed is None else _group_seed(seed, rows)
            opts = dict(options or {})
            if targets is not None:
                opts["target"] = targets[rows]
            outs.append(group.reset(seed=own, options=opts))
        info = {"target": np.concatenate([o[1]["target"] for o in outs]), "tank": self.row_tanks}
        return _join([o[0] for o in outs]), info

    def step(
        self, actions: NDArray[np.float32]
    ) -> tuple[Obs, NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_], dict[str, Any]]:
        """Step every group; see :class:`~aftir_rl.envs.ftl.env.ArmFTLVectorEnv`."""
        a = np.asarray(actions)
        if a.shape != self.action_space.shape:
            raise InvalidActionError(
                f"invalid action of shape {a.shape}: expected {self.action_space.shape} "
                "finite values in [-1, 1]"
            )
        outs = [g.step(a[rows]) for g, rows in zip(self.groups, self._slices())]
        if self.stream is not None:
            outs = [self._move_on(g, out) for g, out in enumerate(outs)]
        obs = _join([o[0] for o in outs])
        reward, terminated, truncated = (np.concatenate([o[i] for o in outs]) for i in (1, 2, 3))
        return (
            obs,
            reward,
            terminated,
            truncated,
            _join_infos([o[0] for o in outs], [o[4] for o in outs]),
        )

    def _restart_stream(self) -> None:
        """Every group back to its first wing of the stream, no episodes counted."""
        assert self.stream is not None
        for g in range(len(self.groups)):
            if self.pool.names[g] != self.stream.spec_at(g):
                self._replace_group(g, self.stream.spec_at(g))
        self._episodes[:] = 0
        self.tanks_met = len(self.groups)

    def _replace_group(self, g: int, spec: str) -> ArmFTLVectorEnv:
        """Group ``g`` in the tank ``spec`` from now on (the old tank's env is closed)."""
        self.groups[g].close()
        self.pool.tanks[g] = load_tank(spec)
        self.pool.names[g] = spec
        size = int(self.starts[g + 1] - self.starts[g])
        self.groups[g] = ArmFTLVectorEnv(size, **{**self._group_args, "tank": self.pool.tanks[g]})
        self.row_tanks[self.starts[g] : self.starts[g + 1]] = [spec] * size
        return self.groups[g]

    def _move_on(self, g: int, out: tuple[Any, ...]) -> tuple[Any, ...]:
        """A stream's group ``g`` after its step: in the next wing once it has its episodes.

        The rows still running end here (truncated) with their last observations; the new
        tank's env is reset (seeded from the env's seed, the group and the tank) and its rows
        start on the next step (``NextStep``) or in this one's returned observations
        (``SameStep``, the last ones in ``info["final_obs"]``).
        """
        obs, reward, terminated, truncated, info = out
        ended = terminated | truncated
        self._episodes[g] += int(ended.sum())
        if self._episodes[g] < self.tank_episodes:
            return out
        assert self.stream is not None
        spec = self.stream.spec_at(self.tanks_met)
        seed = self.stream.first + self.tanks_met
        self.tanks_met += 1
        self._episodes[g] = 0
        new = self._replace_group(g, spec)
        own = None
        if self._seed is not None:
            own = int(np.random.SeedSequence([self._seed, g, seed]).generate_state(1)[0])
        first_obs, _ = new.reset(seed=own)
        running = np.flatnonzero(~ended)
        truncated = truncated | ~ended
        if self.autoreset_mode is AutoresetMode.SAME_STEP:
            finals = info.get("final_obs")
            finals = np.full(len(ended), None, dtype=object) if finals is None else finals.copy()
            for i in running.tolist():
                finals[i] = {key: value[i].copy() for key, value in obs.items()}
            info = {k: v for k, v in info.items() if not k.lstrip("_").startswith("final_")}
            info["final_obs"], info["_final_obs"] = finals, np.ones(len(ended), dtype=bool)
            obs = first_obs
        else:
            new.prev_done[:] = True  # the next step starts every row, in the new tank
        return obs, reward, terminated, truncated, info

    def close_extras(self, **kwargs: Any) -> None:
        """Close every group (none when the constructor refused its arguments)."""
        for group in getattr(self, "groups", ()):
            group.close()


def _first_tanks(
    tank: object, num_envs: int, tanks_at_once: int | None, tank_episodes: int | None
) -> tuple[list[str], int]:
    """A pool's tanks, or a stream's first ``tanks_at_once``; a stream's ``tank_episodes``."""
    stream = stream_spec(tank)
    if stream is None:
        specs = pool_specs(tank)
        if specs is None:
            raise ConfigError(
                "ArmFTLPoolVectorEnv needs a pool tank='wing:BAYS:FIRST-LAST' or a stream "
                "'wing:BAYS:FIRST+'"
            )
        if tanks_at_once is not None or tank_episodes is not None:
            raise ConfigError("tanks_at_once and tank_episodes are a stream's (wing:B:F+)")
        return specs, 0
    at_once = 8 if tanks_at_once is None else tanks_at_once
    episodes = 256 if tank_episodes is None else tank_episodes
    for name, value in (("tanks_at_once", at_once), ("tank_episodes", episodes)):
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise ConfigError(f"{name} must be a whole number of at least 1, got {value!r}")
    return [stream.spec_at(g) for g in range(min(at_once, num_envs))], episodes


def _group_seed(seed: int | Sequence[int], rows: slice) -> int | list[int]:
    """A group's seeds: row ``i`` seeded ``seed + i``."""
    if isinstance(seed, int):
        return seed + int(rows.start)
    return [int(s) for s in seed[rows]]


def _join(parts: list[Obs]) -> Obs:
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


def _join_infos(obs: list[Obs], infos: list[dict[str, Any]]) -> dict[str, Any]:
    """The groups' infos row by row; a ``SameStep`` end's entries where any group has one."""
    finals = ("final_obs", "_final_obs", "final_info", "_final_info")
    keys = [k for k in infos[0] if k not in finals]
    out: dict[str, Any] = {k: np.concatenate([i[k] for i in infos]) for k in keys}
    if any("final_obs" in i for i in infos):
        final_obs = np.concatenate(
            [
                i.get("final_obs", np.full(len(o["observation"]), None, dtype=object))
                for i, o in zip(infos, obs)
            ]
        )
        out.update(same_step_finals(final_obs, out))
    return out
