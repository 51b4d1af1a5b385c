"""``AFTIR-ArmFTL-v0``: the whole arm deployed by follow-the-leader, goal-conditioned, batched.

:class:`ArmFTLEnv` (one arm) and :class:`ArmFTLVectorEnv` (``num_envs`` arms in one numpy pass,
``gym.make_vec(..., vectorization_mode="vector_entry_point")``) are thin shells around the
same parts (:class:`~aftir_rl.envs.ftl.task.FTLParts`): the state
(:class:`~aftir_rl.envs.ftl.state.FTLBatch`), the reward
(:class:`~aftir_rl.envs.ftl.reward.FTLReward`) and the target sampler
(:class:`~aftir_rl.envs.ftl.targets.TargetSampler`), so row ``i`` of a vector env seeded
``seed`` has exactly the transitions of a single env seeded ``seed + i``. The agent steers the
route section the tip is tracing and pushes or pulls the linear module; the body follows the
traced route (:mod:`aftir_rl.planning.ftl.model`). Options: :mod:`aftir_rl.envs.ftl.spec`. The
model, the collision check and the reward are described in docs/envs/armftl.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.errors import ConfigError, TargetError
from aftir_rl.core.robot import Posture, body_points
from aftir_rl.envs.ftl.pool import (
    STREAM_KWARGS,
    TankPool,
    evaluation_tank,
    pool_specs,
    stream_spec,
)
from aftir_rl.envs.ftl.spec import FTLSpec
from aftir_rl.envs.ftl.task import (
    build_parts,
    check_action,
    check_options,
    goal_clip,
    observations,
    spaces_of,
)

__all__ = ["ArmFTLEnv", "ArmFTLVectorEnv", "same_step_finals"]


class ArmFTLEnv(gym.Env[dict[str, NDArray[np.float32]], NDArray[np.float32]]):
    """The whole arm, deployed through the panel by follow-the-leader, reaching targets.

    ## Description

    The AFTIR arm (``n_sections`` sections, default the tank's maximum, 12 × 50 cm in the
    reference tank) on its linear module. The agent steers the section the tip is tracing and
    pushes or pulls the module; the body follows the traced route (docs/envs/armftl.md). The task:
    bring the tip within ``success_tolerance`` of a target anywhere free in the tank (both bays
    by default), through the hatch for bay-2 targets, without contact.

    ## Action Space

    ``Box(-1, 1, (3,), float32)``: the steering (two components) and the insertion (scaled by
    ``push_step`` [cm], ``s`` clipped to ``[0, N·l]``). With ``steer="increment"`` (the default)
    the steering is the change of the steered ``κ`` (scaled by ``kappa_step`` [rad], ``|κ|``
    clipped to ``θ_max``); with ``steer="target"`` it is the bend the steered section should
    have, ``κ* = θ_max·a`` (``|κ*|`` clipped to ``θ_max``), which ``κ`` approaches by at most
    ``kappa_step`` per component and step: the same bending rates, but the policy names a bend
    rather than a rate, and holds a bend by holding its action.

    ## Observation Space

    ``Dict``: ``achieved_goal`` (tip) and ``desired_goal`` (target), ``Box(float32, (3,))`` in cm
    (the tank box grown by 100 cm); ``observation``, ``Box(-10, 10, float32)``: ``dis/(N·l)``,
    ``k/N``, the steered ``κ/θ_max``, every section's ``θ/θ_max``, ``sin φ``, ``cos φ``, the tip
    (cm/100), its heading, the body's surface clearance (cm/10, clipped to ±1), the clearance at
    10, 25 and 50 cm along 7 rays from the tip (heading, ±x, ±y, ±z; cm/50, clipped to ±1) and
    the heights of the last three section ends (cm/100).

    ## Starting State

    Straight, the tip ``start_height`` (10 cm) above the floor.

    ## Rewards

    Progress ``(d_prev − d)/10`` [per cm], the raster-detour potential term when ``shaping``,
    ``+10`` on success, ``−10`` on contact, ``−step_cost`` per step: :meth:`compute_reward`
    (docs/envs/armftl.md).

    ## Episode End

    Terminated on success (tip within ``success_tolerance`` and no contact) or contact (surface
    clearance below ``margin``); truncated by ``max_episode_steps`` (300 at registration).

    ## Arguments

    - ``tank``: tank name, YAML path, generator spec ``wing:BAYS:SEED``, a pool
      ``wing:BAYS:FIRST-LAST`` drawn per episode (:mod:`aftir_rl.envs.ftl.pool`; the batched
      env gives each its group of rows), or a stream ``wing:BAYS:FIRST+``: the batched env
      moves along it (with ``tanks_at_once`` and ``tank_episodes``), this env takes its first
      16 wings as a pool; ``n_sections``: default the tank arm's maximum.
    - ``target``: fixed target [cm] for every episode; default drawn per episode with
      ``np_random``, uniformly among points ``target_clearance`` (10 cm) from every surface and
      20 cm from the start, in ``bay`` (1 to the number of bays between the tank's baffles, or
      None for the whole tank).
    - ``success_tolerance`` (2 cm), ``margin`` (1 cm), ``kappa_step`` (0.1 rad), ``push_step``
      (5 cm), ``start_height`` (10 cm), ``samples_per_section`` (10).
    - ``shaping`` (False): the reward's potential term, ``True`` or ``"raster"`` (the raster
      BFS's detour) or ``"field"`` (the guide field's cost-to-go; docs/envs/armftl.md).
    - ``guide`` (False): append to ``observation`` what the way to *this* target looks like: the
      free-space distance-to-go (cm/100, at most 10), then, in the frame the steered section
      bends in (:meth:`FTLBatch.steering_frames`), the unit way to the next point of the
      shortest way (:class:`~aftir_rl.envs.ftl.fields.FieldGuide`), ``(target − tip)/100``,
      the tip's heading, and the unit directions to the points of that way 3 and 6 grid steps
      ahead (about 30-50 and 60-100 cm; :meth:`FieldGuide.lookahead`), so the policy sees a turn
      coming while the arm can still bend into it. These depend on the goal, so HER's relabelled
      goals would not match them: use it with PPO, not HER.
    - ``near_goal`` (False): append to ``observation`` the target's offset from the tip at a
      fine scale, in the steering frame: ``(target − tip)/max(d, 10 cm)``, the unit way beyond
      10 cm and within it the offset in tenths of 10 cm, ten times the resolution of the
      guide's ``(target − tip)/100`` (:meth:`FTLBatch.near_goal_columns`), for the last
      centimetres. Goal-dependent like ``guide``: not with HER.
    - ``detour_bias`` (0): the fraction of drawn targets whose density is weighted by
      ``1 + e``, ``e`` the detour of the raster's shortest way from the start beyond the straight
      (Manhattan) one, in cells: targets behind obstacles (in bay 2, far from the hatch) come up
      more often; the other targets are uniform as before. A curriculum knob for training; the
      evaluations of ``train`` and ``evaluate`` draw their targets uniformly.
    - ``corner_bias`` (0): the fraction of drawn targets drawn in the corners of the target
      region instead (``target_clearance`` to ``target_clearance`` + 15 cm inward from one of
      its eight corners, free as the others): where the arm bends most with walls on three
      sides. A curriculum knob for training, like ``detour_bias`` (not both at once).
    - ``failure_bias`` (0): the fraction of drawn targets whose density is weighted by the
      running failure rate of the episodes aimed at their raster cell
      (:class:`~aftir_rl.envs.ftl.targets.FailureRates`, kept by the env from its own episodes;
      cells never aimed at count as hard): training comes back to where the policy still fails,
      wherever that is. With ``corner_bias`` the corner targets are weighted too; not with
      ``detour_bias``. Training-only, like ``detour_bias``; the rates start again with each
      env (a resumed run learns them anew), and the vector env's targets then depend on its
      rows' outcomes, not on the seeds alone.
    - ``slack`` (0 cm): training demands this much more than the success rule: the tip within
      ``success_tolerance − slack``, the surface clearance at least ``margin + slack``, so that
      a policy measured by the rule itself has that much in hand rather than ending its
      episodes exactly at the 2 cm tolerance or the 1 cm margin (docs/experiments.md measures
      it). Training-only, like ``detour_bias``: evaluations drop it.
    - ``steer`` (``"increment"``): what the two steering actions command, a change of ``κ``
      or ``"target"``, the bend itself (Action Space).
    - ``step_cost`` (0): a cost paid on every step (at most 0.03, so that ending an episode
      on contact, −10, never pays better than waiting out the 300 steps). A policy that
      stops a few cm short of a target it cannot reach by pushing on earns 0 per step there
      without it; with it, stopping costs ``step_cost/(1 − γ)``, and pulling back to bend
      again becomes worth trying.
    - ``render_mode``: ``"rgb_array"``.

    ``reset(options={"target": (x, y, z)})`` sets the target of one episode; with a pool,
    ``options={"tank": k}`` its tank (an index into the pool, or a spec of it).

    ## Version History

    - v0: initial version.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, *, render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(f"render_mode must be 'rgb_array' or None, got {render_mode!r}")
        self.render_mode = render_mode
        if stream_spec(kwargs.get("tank")) is not None:  # its first wings, as a pool
            kwargs = {k: v for k, v in kwargs.items() if k not in STREAM_KWARGS}
            kwargs["tank"] = evaluation_tank(kwargs["tank"])
        spec = FTLSpec.from_kwargs(**kwargs)
        specs = pool_specs(spec.task.tank)
        #: The tanks drawn per episode (``tank="wing:BAYS:FIRST-LAST"``), or None.
        self.pool = None if specs is None else TankPool(specs)
        #: The goal space's corners shared by a pool's tanks, or None (the tank's own).
        self.goal_bounds = None if self.pool is None else self.pool.goal_bounds
        self._spec, self._tank_index = spec, 0
        self._use(spec if self.pool is None else self.pool.spec_for(spec, 0))
        self.arm = self.tank.arm
        # gymnasium types a Dict space's elements as dict[str, Space], not dict[str, element]
        self.action_space, self.observation_space = spaces_of(self.batch)
        self._tips: list[NDArray[np.float64]] = []
        #: The shaping's potential at the tip (NaN: not known; see ``FTLReward.step``).
        self._potential: NDArray[np.float64] | None = np.full(1, np.nan)
        self._achieved = np.zeros((1, 3), dtype=np.float32)
        self._open = False  # an episode has steps and has not ended (for failure_bias)
        self._renderer: Any = None

    def _use(self, spec: FTLSpec) -> None:
        """Build the env's parts for ``spec`` (again when a pool's episode draws another tank)."""
        parts = build_parts(spec, 1, self.goal_bounds)
        #: The arm's state, the reward and the target sampler (:mod:`aftir_rl.envs.ftl.task`).
        self.batch, self.reward, self.sampler = parts
        self.tank = self.batch.tank

    def compute_reward(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> NDArray[np.float64] | float:
        """The step reward itself, so HER relabels with it (``FTLReward.compute_reward``)."""
        return self.reward.compute_reward(achieved_goal, desired_goal, info)

    def compute_terminated(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> NDArray[np.bool_] | bool:
        """:meth:`~aftir_rl.envs.ftl.reward.FTLReward.compute_terminated`: success or contact."""
        return self.reward.compute_terminated(achieved_goal, desired_goal, info)

    @property
    def target(self) -> NDArray[np.float64]:
        """The episode's target [cm]."""
        return self.batch.target[0].copy()

    @property
    def tip(self) -> NDArray[np.float64]:
        """The tip's position [cm]."""
        return self.batch.tip[0].copy()

    @property
    def posture(self) -> Posture:
        """The current joint variables ``(dis, θ, φ)``."""
        b = self.batch
        return Posture(b.dis[0], b.theta[0], b.phi[0])

    @property
    def route_kappa(self) -> NDArray[np.float64]:
        """The traced route's ``κ`` ``(k + 1, 2)`` [rad], the steered section last."""
        return self.batch.kappa[0, : self.batch.k[0] + 1].copy()

    @property
    def insertion(self) -> float:
        """The tip's arc length ``s`` along the route, from the floor [cm]."""
        return float(self.batch.s[0])

    def body(self, points_per_section: int = 10) -> NDArray[np.float64]:
        """Backbone points of the current posture [cm]."""
        b = self.batch
        return body_points(b.dis[0], b.theta[0], b.phi[0], b.l, points_per_section)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, Any]]:
        """Straighten the arm just inside the panel and set a target."""
        super().reset(seed=seed)
        options = check_options(options, ("target", "tank") if self.pool else ("target",))
        if self._open:  # the last episode ended without success (truncated or left)
            self.sampler.record(self.batch.target, [False])
        self._open = False
        if self.pool is not None:  # this episode's tank
            index = self.pool.draw(self.np_random)
            if options.get("tank") is not None:
                index = self.pool.index(options["tank"])
            if index != self._tank_index:
                self._use(self.pool.spec_for(self._spec, index))
                self._tank_index = index
                self._renderer = None  # drawn again in the new tank
        if options.get("target") is not None:
            target = self.batch.check_target(options["target"])
        else:
            target = self.sampler.draw([self.np_random])[0]
        self.batch.reset_rows(np.array([0]), target[None])
        self._potential = np.full(1, np.nan)
        self._tips = [self.tip]
        info = {
            "distance_cm": float(np.linalg.norm(self.tip - target)),
            "target": target.copy(),
            "tank": self.tank.source or self.tank.name,
        }
        rows = observations(self.batch)
        self._achieved = rows["achieved_goal"].copy()  # the next step's previous tip, clipped
        return {k: v[0] for k, v in rows.items()}, info

    def step(
        self, action: NDArray[np.float32]
    ) -> tuple[dict[str, NDArray[np.float32]], SupportsFloat, bool, bool, dict[str, Any]]:
        """Steer and push; see the class docstring for rewards and termination."""
        a = check_action(action, self.action_space.shape)
        b = self.batch
        b.step(a[None])
        prev = self._achieved  # the previous tip, as the last observation held it
        self._tips.append(self.tip)
        rows = observations(self.batch)
        self._achieved = rows["achieved_goal"].copy()
        contact = b.contact
        # compute_reward's formula on the same float32 goals
        reward, distance, self._potential = self.reward.step(
            rows["achieved_goal"], rows["desired_goal"], prev, contact, self._potential
        )
        hit = bool(contact[0])
        success = bool(distance[0] < b.success_tolerance) and not hit
        self._open = not (success or hit)
        if not self._open:
            self.sampler.record(b.target, [success])
        info: dict[str, Any] = {
            "prev_achieved_goal": prev[0],
            "contact": hit,
            "is_success": success,
            "collision": hit,
            "distance_cm": float(distance[0]),
            "min_clearance_cm": float(b.surface_clearance[0]),
        }
        obs = {k: v[0] for k, v in rows.items()}
        return obs, float(reward[0]), success or hit, False, info

    def render(self) -> NDArray[np.uint8] | None:  # type: ignore[override]
        """The tank, the arm, its tip path and the target (``rgb_array``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode= to make()")
            return None
        if self._renderer is None:
            from aftir_rl.viz.plotting import PathRenderer

            self._renderer = PathRenderer(self.tank, title="AFTIR-ArmFTL")
        return self._renderer.render(np.array(self._tips), self.target, arms=[self.body()])


def _refuse_stream(tank: object) -> None:
    if stream_spec(tank) is not None:
        raise ConfigError(
            f"tank {tank!r} is a stream of generated wings: the batched env's, "
            "gym.make_vec('AFTIR-ArmFTL-v0', n, tank=...)"
        )


def same_step_finals(final_obs: NDArray[np.object_], info: dict[str, Any]) -> dict[str, Any]:
    """The ``info`` entries of a ``SameStep`` autoreset, in Gymnasium's ``SyncVectorEnv`` form.

    ``final_obs``: one entry per row, the row's last observation where it ended and None
    elsewhere; ``final_info``: the step's per-row ``info`` arrays, each with its ``_key`` mask;
    ``_final_obs`` and ``_final_info``: which rows ended.
    """
    ended = np.array([o is not None for o in final_obs], dtype=bool)
    final_info: dict[str, Any] = {}
    for key, value in info.items():
        final_info[key] = value.copy()
        final_info[f"_{key}"] = ended.copy()
    return {
        "final_obs": final_obs,
        "_final_obs": ended,
        "final_info": final_info,
        "_final_info": ended.copy(),
    }


class ArmFTLVectorEnv(VectorEnv[dict[str, NDArray[np.float32]], NDArray[np.float32], Any]):
    """``num_envs`` :class:`ArmFTLEnv` s stepped together in numpy (autoreset: next step).

    Same arguments as :class:`ArmFTLEnv` plus ``num_envs``, ``max_episode_steps``
    (truncation) and ``goal_bounds`` (the goal space's corners, shared by the groups of
    :class:`~aftir_rl.envs.ftl.pool_vector.ArmFTLPoolVectorEnv`), and one tank: a pool goes to
    :func:`~aftir_rl.envs.ftl.pool_vector.make_vector_env`. Row ``i`` draws its targets from its
    own generator, seeded ``seed + i`` by ``reset(seed=seed)``, so it reproduces a single env
    seeded ``seed + i``. As in Gymnasium's ``CartPoleVectorEnv``, a row that ended is reset by
    the next ``step`` (which returns its first observation with reward 0 and no termination,
    ignoring that row's action).
    ``reset(options={"target": ...})`` takes one target for all rows or one per row ``(B, 3)``.
    ``info`` holds per-row arrays ``prev_achieved_goal``, ``contact``, ``is_success``,
    ``distance_cm`` and ``min_clearance_cm``. With ``autoreset_mode="SameStep"`` rows that end are
    reset within the step instead and the step returns their first observations; their last ones
    are where Gymnasium's ``SyncVectorEnv`` puts them (:func:`same_step_finals`), which is what
    TorchRL's ``GymWrapper`` and SB3's ``VecEnv`` adapter
    (:class:`aftir_rl.rl.sb3.vec_adapter.SB3VectorEnv`) read.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int = 300,
        *,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
        goal_bounds: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
        **kwargs: Any,
    ) -> None:
        #: The goal space's corners [cm], or None: the tank's box grown by 1 m.
        self.goal_bounds = goal_bounds
        if render_mode is not None:
            raise ConfigError("ArmFTLVectorEnv does not render; use ArmFTLEnv for pictures")
        if num_envs < 1 or max_episode_steps < 1:
            raise ConfigError("num_envs and max_episode_steps must be at least 1")
        self.num_envs = int(num_envs)
        self.max_episode_steps = int(max_episode_steps)
        self.render_mode = None
        spec = FTLSpec.from_kwargs(**kwargs)
        _refuse_stream(spec.task.tank)
        if pool_specs(spec.task.tank) is not None:
            raise ConfigError(
                "a tank pool (wing:BAYS:FIRST-LAST) has one tank per group of rows: "
                "ArmFTLPoolVectorEnv, or gym.make_vec('AFTIR-ArmFTL-v0', n, tank=...)"
            )
        parts = build_parts(spec, self.num_envs, goal_bounds)
        #: The arms' state, the reward and the target sampler (:mod:`aftir_rl.envs.ftl.task`).
        self.batch, self.reward, self.sampler = parts
        self.tank = self.batch.tank
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ConfigError(
                f"autoreset_mode must be 'NextStep' or 'SameStep', got {autoreset_mode!r}"
            ) from None
        if self.autoreset_mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ConfigError("autoreset_mode must be 'NextStep' or 'SameStep'")
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.single_action_space, self.single_observation_space = spaces_of(self.batch)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._rngs = [seeding.np_random()[0] for _ in range(self.num_envs)]
        self.steps = np.zeros(self.num_envs, dtype=np.int64)
        self.prev_done = np.zeros(self.num_envs, dtype=bool)
        #: The shaping's potential at each row's tip (NaN: not known; see ``FTLReward.step``).
        self._potential = np.full(self.num_envs, np.nan)
        self._targets_option: NDArray[np.float64] | None = None

    def compute_reward(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> NDArray[np.float64] | float:
        """:meth:`~aftir_rl.envs.ftl.reward.FTLReward.compute_reward`, vectorised over rows."""
        return self.reward.compute_reward(achieved_goal, desired_goal, info)

    def compute_terminated(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> NDArray[np.bool_] | bool:
        """:meth:`~aftir_rl.envs.ftl.reward.FTLReward.compute_terminated`, vectorised over rows."""
        return self.reward.compute_terminated(achieved_goal, desired_goal, info)

    def _new_targets(self, rows: NDArray[np.int64]) -> NDArray[np.float64]:
        if self._targets_option is not None:
            return self._targets_option[rows]
        return self.sampler.draw([self._rngs[i] for i in rows])

    def reset(
        self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, Any]]:
        """Reset every row; ``seed`` seeds row ``i`` with ``seed + i`` (or a list, one each)."""
        if seed is not None:
            seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else seed
            if len(seeds) != self.num_envs:
                raise ConfigError(f"reset got {len(seeds)} seeds for {self.num_envs} envs")
            self._rngs = [seeding.np_random(int(s))[0] for s in seeds]
            self._np_random, self._np_random_seed = seeding.np_random(seeds[0])
        options = check_options(options)
        self._targets_option = None
        if options.get("target") is not None:
            t = np.asarray(options["target"], dtype=np.float64)
            rows = t.reshape(-1, 3) if t.size % 3 == 0 else t
            if rows.ndim != 2 or len(rows) not in (1, self.num_envs):
                raise TargetError(f"target must be (3,) or ({self.num_envs}, 3), got {t.shape}")
            checked = np.array([self.batch.check_target(r) for r in rows])
            self._targets_option = np.broadcast_to(checked, (self.num_envs, 3)).copy()
        every = np.arange(self.num_envs)
        self.batch.reset_rows(every, self._new_targets(every))
        self._potential = np.full(self.num_envs, np.nan)
        self.steps[:] = 0
        self.prev_done[:] = False
        return observations(self.batch), {"target": self.batch.target.copy()}

    def step(
        self, actions: NDArray[np.float32]
    ) -> tuple[
        dict[str, NDArray[np.float32]],
        NDArray[np.float64],
        NDArray[np.bool_],
        NDArray[np.bool_],
        dict[str, Any],
    ]:
        """Step every row; rows that ended on the previous step are reset instead."""
        a = check_action(actions, self.action_space.shape)
        b = self.batch
        done_rows = np.flatnonzero(self.prev_done)
        if len(done_rows):
            a[done_rows] = 0.0
            b.reset_rows(done_rows, self._new_targets(done_rows), refresh=False)
            # (their rewards are 0 this step; their potentials at the new start follow from it)
        prev_tip = b.step(a)
        prev_tip[done_rows] = b.tip[done_rows]
        obs = observations(self.batch)
        prev = goal_clip(self.batch, prev_tip)
        contact = b.contact.copy()
        info: dict[str, Any] = {"prev_achieved_goal": prev, "contact": contact}
        # compute_reward's formula on the same float32 goals
        reward, distance, potential = self.reward.step(
            obs["achieved_goal"], obs["desired_goal"], prev, contact, self._potential
        )
        if potential is not None:  # the next step's potentials at its previous tips
            self._potential = potential
        success = (distance < b.success_tolerance) & ~contact
        terminated = success | contact
        self.steps += 1
        truncated = self.steps >= self.max_episode_steps
        reward[done_rows] = 0.0
        terminated[done_rows] = False
        truncated[done_rows] = False
        self.steps[done_rows] = 0
        info.update(
            is_success=success,
            collision=contact,
            distance_cm=distance,
            min_clearance_cm=b.surface_clearance.copy(),
        )
        done = terminated | truncated
        ended = np.flatnonzero(done)
        self.sampler.record(b.target[ended], success[ended])
        if self.autoreset_mode is AutoresetMode.NEXT_STEP:
            self.prev_done = done
        elif done.any():  # SAME_STEP: the last observations go to info, the rows start again
            rows = np.flatnonzero(done)
            final_obs = np.full(self.num_envs, None, dtype=object)
            for i in rows.tolist():
                final_obs[i] = {key: value[i].copy() for key, value in obs.items()}
            info.update(same_step_finals(final_obs, info))
            b.reset_rows(rows, self._new_targets(rows))
            self._potential[rows] = np.nan
            self.steps[rows] = 0
            obs = {k: v.copy() for k, v in obs.items()}
            for key, value in observations(
                self.batch, rows
            ).items():  # only the rows that started again
                obs[key][rows] = value
        return obs, reward, terminated, truncated, info
