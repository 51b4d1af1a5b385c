"""Stable-Baselines3 baselines (PPO, SAC, TD3) on the arm envs, logged like the Q-table runs.

Configuration: ``configs/{ppo,sac,td3}.yaml`` load into :class:`SB3Config`; ``hyperparameters``
go to the algorithm's constructor and are checked against its signature (an unknown key is a
:class:`~aftir_rl.errors.ConfigError` naming the file and the key).

:class:`ArmEvalCallback` runs the deterministic policy on a fixed set of evaluation targets and
logs ``eval/success_rate``, ``eval/tip_error_cm``, ``eval/path_length_cm``,
``eval/collision_rate``, ``eval/min_clearance_cm`` and a picture of the tip path and arm under
``paths/eval`` through the model's SB3 logger, so SB3 runs and Q-learning runs overlay in one
TensorBoard.
Checkpoints are written atomically (temporary file, then rename).
"""

from __future__ import annotations

import dataclasses
import inspect
import io
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Image

from aftir_rl.atomic import atomic_open
from aftir_rl.config import brief, from_mapping, read_yaml, shorten, to_float
from aftir_rl.errors import CheckpointError, ConfigError

__all__ = ["ALGORITHMS", "SB3Config", "load_sb3_config", "ArmEvalCallback", "AtomicCheckpoint",
           "evaluation_targets", "evaluate_policy_on_targets", "load_model"]  # fmt: skip

ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC, "td3": TD3}


@dataclass(frozen=True)
class SB3Config:
    """A run of an SB3 algorithm (``configs/<algo>.yaml``).

    Attributes:
        env_id: environment id (``AFTIR-ArmReach-v0``...).
        total_timesteps: training steps.
        n_envs: parallel envs (subprocesses when more than one).
        eval_freq: environment steps between evaluations.
        eval_targets: number of fixed evaluation targets.
        checkpoint_freq: environment steps between checkpoints.
        policy: SB3 policy name.
        hyperparameters: keyword arguments of the algorithm.
        her: SAC/TD3 with SB3's ``HerReplayBuffer`` (goal-conditioned envs only; future
            strategy, 4 relabelled goals per transition, the infos kept for ``compute_reward``).
        env_kwargs: keyword arguments of the env (plain values, :data:`ENV_KWARGS` only).

    """

    env_id: str = "AFTIR-ArmReach-v0"
    total_timesteps: int = 100_000
    n_envs: int = 1
    eval_freq: int = 10_000
    eval_targets: int = 20
    checkpoint_freq: int = 50_000
    policy: str = "MlpPolicy"
    hyperparameters: dict[str, Any] = field(default_factory=dict)
    her: bool = False
    env_kwargs: dict[str, Any] = field(default_factory=dict)


def load_sb3_config(path: str | os.PathLike[str], algo: str) -> SB3Config:
    """Read and check an SB3 config; numbers written as strings (``3e-4``) are parsed."""
    data = read_yaml(path)
    hyper = data.pop("hyperparameters", None) or {}
    if not isinstance(hyper, dict):
        raise ConfigError(f"{path}: hyperparameters: expected a mapping")
    for key in hyper:
        if not isinstance(key, str):
            raise ConfigError(f"{path}: hyperparameters: unknown key {brief(key)}")
    config = from_mapping(SB3Config, data, str(path))
    allowed = _constructor_keys(algo)
    parsed = {}
    for key, value in hyper.items():
        if key not in allowed:
            raise ConfigError(
                f"{path}: hyperparameters: unknown key {brief(key)} for {algo.upper()}; allowed "
                f"keys are {', '.join(sorted(allowed))}"
            )
        if isinstance(value, str):
            try:
                value = to_float(value, f"{path}: hyperparameters.{key}")
            except ConfigError:
                pass
        parsed[key] = value
    config = SB3Config(**{**config.__dict__, "hyperparameters": parsed})
    check_sb3_config(config, algo, str(path))
    return config


# Bounds of what a config may ask for: each is far above what the shipped configs use, and keeps
# the memory and time of building a model small (a replay buffer of 2e6 transitions of the arm
# envs is about 0.5 GB).
_INT_RANGES: dict[str, tuple[int, int]] = {
    "n_steps": (1, 1_000_000), "batch_size": (1, 1_000_000), "n_epochs": (1, 1000),
    "buffer_size": (1, 2_000_000), "learning_starts": (0, 1_000_000_000),
    "gradient_steps": (-1, 10_000), "policy_delay": (1, 1000),
    "target_update_interval": (1, 1_000_000), "sde_sample_freq": (-1, 1_000_000),
    "stats_window_size": (1, 100_000),
}  # fmt: skip
_FLOAT_RANGES: dict[str, tuple[float, float]] = {
    "learning_rate": (1e-12, 10.0), "gamma": (0.0, 1.0), "gae_lambda": (0.0, 1.0),
    "clip_range": (1e-12, 100.0), "vf_coef": (0.0, 1e6), "max_grad_norm": (1e-12, 1e9),
    "tau": (0.0, 1.0), "target_policy_noise": (0.0, 1e3), "target_noise_clip": (0.0, 1e3),
}  # fmt: skip
_OPTIONAL_FLOATS: dict[str, tuple[float, float]] = {
    "clip_range_vf": (1e-12, 1e6), "target_kl": (1e-12, 1e6),
}  # fmt: skip
_BOOLS = ("normalize_advantage", "use_sde", "use_sde_at_warmup", "optimize_memory_usage")
#: Keys a YAML config cannot give: they take Python objects (classes, noise processes).
_OBJECTS = ("rollout_buffer_class", "rollout_buffer_kwargs", "replay_buffer_class",
            "replay_buffer_kwargs", "action_noise")  # fmt: skip
_POLICY_KWARGS = {"net_arch", "log_std_init", "ortho_init", "n_critics",
                  "share_features_extractor", "squash_output", "full_std", "use_expln"}  # fmt: skip
#: Bounds of the fields of :class:`SB3Config`.
_CONFIG_RANGES = {"total_timesteps": (1, 1_000_000_000), "n_envs": (1, 64),
                  "eval_freq": (1, 1_000_000_000), "eval_targets": (1, 1000),
                  "checkpoint_freq": (1, 1_000_000_000)}  # fmt: skip


def _check_range(value: Any, lo: float, hi: float, where: str, integer: bool) -> None:
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{where}: expected {kind} from {lo:g} to {hi:g}, got {brief(value)}")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if integer and math.isfinite(number) and not number.is_integer():
        raise ConfigError(f"{where}: expected {kind} from {lo:g} to {hi:g}, got {brief(value)}")
    if not (math.isfinite(number) and lo <= number <= hi):
        raise ConfigError(f"{where}: expected {kind} from {lo:g} to {hi:g}, got {brief(value)}")


def _check_net_arch(value: Any, where: str) -> None:
    def layers(v: Any, w: str) -> None:
        if not isinstance(v, list) or len(v) > 8:
            raise ConfigError(f"{w}: expected a list of at most 8 layer widths, got {brief(v)}")
        for i, width in enumerate(v):
            _check_range(width, 1, 4096, f"{w}[{i}]", integer=True)

    if isinstance(value, dict):
        for key, v in value.items():
            if key not in ("pi", "vf", "qf"):
                raise ConfigError(f"{where}: unknown key {brief(key)}; allowed keys are pi, qf, vf")
            layers(v, f"{where}.{key}")
    else:
        layers(value, where)


def check_sb3_config(config: SB3Config, algo: str, source: str) -> None:
    """Check every value of an SB3 config before anything is built: types, ranges, sizes.

    Raises:
        ConfigError: naming ``source`` and the key.

    """
    from aftir_rl.safety import registered_env_id

    registered_env_id(config.env_id, source)
    for key, (lo, hi) in _CONFIG_RANGES.items():
        _check_range(getattr(config, key), lo, hi, f"{source}: {key}", integer=True)
    aliases = getattr(ALGORITHMS[algo], "policy_aliases", {})
    if config.policy not in aliases:
        raise ConfigError(
            f"{source}: policy: {brief(config.policy)} is not a {algo.upper()} policy; use one of "
            f"{', '.join(aliases)}"
        )
    for key, value in config.hyperparameters.items():
        where = f"{source}: hyperparameters.{key}"
        if key in _INT_RANGES:
            _check_range(value, *_INT_RANGES[key], where, integer=True)
        elif key in _FLOAT_RANGES:
            _check_range(value, *_FLOAT_RANGES[key], where, integer=False)
        elif key in _OPTIONAL_FLOATS:
            if value is not None:
                _check_range(value, *_OPTIONAL_FLOATS[key], where, integer=False)
        elif key in _BOOLS:
            if not isinstance(value, bool):
                raise ConfigError(f"{where}: expected true or false, got {brief(value)}")
        elif key in _OBJECTS:
            raise ConfigError(f"{where}: takes a Python object, which a config file cannot give")
        elif key == "ent_coef" or key == "target_entropy":
            auto = isinstance(value, str) and (value == "auto" or value.startswith("auto_"))
            if not (auto and algo == "sac"):
                _check_range(value, -1e6 if key == "target_entropy" else 0.0, 1e6, where, False)
            elif value.startswith("auto_"):
                try:
                    float(value[5:])
                except ValueError:
                    raise ConfigError(f"{where}: expected 'auto' or 'auto_<number>'") from None
        elif key == "train_freq":
            ok = isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= 10**6
            if isinstance(value, list) and len(value) == 2:
                ok = value[1] in ("step", "episode")
                _check_range(value[0], 1, 10**6, f"{where}[0]", integer=True)
            if not ok:
                raise ConfigError(f"{where}: expected N or [N, step|episode], got {brief(value)}")
        elif key == "device":
            if value not in ("auto", "cpu", "cuda"):
                raise ConfigError(f"{where}: expected auto, cpu or cuda, got {brief(value)}")
        elif key == "policy_kwargs":
            if not isinstance(value, dict):
                raise ConfigError(f"{where}: expected a mapping, got {brief(value)}")
            for k, v in value.items():
                if k not in _POLICY_KWARGS:
                    raise ConfigError(
                        f"{where}: unknown or unsupported key {brief(k)}; allowed keys are "
                        f"{', '.join(sorted(_POLICY_KWARGS))}"
                    )
                if k == "net_arch":
                    _check_net_arch(v, f"{where}.net_arch")
                elif k in ("ortho_init", "share_features_extractor", "squash_output", "full_std",
                           "use_expln"):  # fmt: skip
                    if not isinstance(v, bool):
                        raise ConfigError(f"{where}.{k}: expected true or false, got {brief(v)}")
                elif k == "n_critics":
                    _check_range(v, 1, 10, f"{where}.{k}", integer=True)
                else:
                    _check_range(v, -20, 20, f"{where}.{k}", integer=False)
        elif not (value is None or isinstance(value, (bool, int, float, str))):
            raise ConfigError(f"{where}: expected a plain value, got {brief(value)}")
    batch, steps = config.hyperparameters.get("batch_size"), config.hyperparameters.get("n_steps")
    if algo == "ppo" and steps is not None and steps * config.n_envs < 2:
        raise ConfigError(f"{source}: hyperparameters.n_steps: n_steps * n_envs must exceed 1")
    if algo == "ppo" and batch is not None and batch < 2:
        raise ConfigError(f"{source}: hyperparameters.batch_size: must be at least 2 for PPO")
    check_goal_settings(config, algo, source)


def sb3_config_from_run(data: Any, source: str) -> tuple[str, SB3Config]:
    """``(algo, config)`` from a run directory's ``config.json``, every key checked.

    Raises:
        CheckpointError: a key this package does not write, or a value out of range.

    """
    if not isinstance(data, dict):
        raise CheckpointError(f"{source}: expected a JSON object")
    algo = data.get("algo")
    if algo not in ALGORITHMS:
        raise CheckpointError(f"{source}: algo must be one of {', '.join(ALGORITHMS)}")
    fields = {f.name for f in dataclasses.fields(SB3Config)}
    written = fields | {"algo", "seed", "resume"}
    unknown = sorted(set(data) - written, key=str)
    if unknown:
        raise CheckpointError(f"{source}: unknown key {brief(unknown[0])}; not a training run's")
    try:
        kwargs = {k: v for k, v in data.items() if k in fields}
        hyper = kwargs.pop("hyperparameters", {}) or {}
        config = from_mapping(SB3Config, kwargs, source)
        if not isinstance(hyper, dict):
            raise ConfigError(f"{source}: hyperparameters: expected a mapping")
        allowed = _constructor_keys(algo)
        for key in hyper:
            if key not in allowed:
                raise ConfigError(f"{source}: hyperparameters: unknown key {brief(key)}")
        config = dataclasses.replace(config, hyperparameters=dict(hyper))
        check_sb3_config(config, algo, source)
    except ConfigError as exc:
        raise CheckpointError(str(exc)) from None
    return algo, config


#: Env keyword arguments a config may give, per env id, with their types; none of them changes
#: the env's spaces, so a model loads with the env's defaults.
ENV_KWARGS: dict[str, dict[str, tuple[type, ...]]] = {
    "AFTIR-ArmFTL-v0": {
        "bay": (int, type(None)), "shaping": (bool,), "target_clearance": (int, float),
        "success_tolerance": (int, float), "margin": (int, float), "kappa_step": (int, float),
        "push_step": (int, float), "start_height": (int, float),
    },
}  # fmt: skip
#: Goal-conditioned envs (``Dict`` observations with ``compute_reward``): the ones HER takes.
GOAL_ENV_IDS = ("AFTIR-ArmFTL-v0",)
#: HerReplayBuffer's settings when ``her`` is on.
HER_KWARGS = {"n_sampled_goal": 4, "goal_selection_strategy": "future", "copy_info_dict": True}


def check_goal_settings(config: SB3Config, algo: str, source: str) -> None:
    """Check ``her`` and ``env_kwargs`` of a config (plain values of known keys only).

    Raises:
        ConfigError: naming ``source`` and the key.

    """
    bare = config.env_id.removeprefix("aftir_rl:")
    if not isinstance(config.her, bool):
        raise ConfigError(f"{source}: her: expected true or false, got {brief(config.her)}")
    if config.her and (algo not in ("sac", "td3") or bare not in GOAL_ENV_IDS):
        raise ConfigError(
            f"{source}: her: only SAC and TD3 on {', '.join(GOAL_ENV_IDS)} use HER, not "
            f"{algo.upper()} on {brief(config.env_id)}"
        )
    if not isinstance(config.env_kwargs, dict):
        raise ConfigError(
            f"{source}: env_kwargs: expected a mapping, got {brief(config.env_kwargs)}"
        )
    allowed = ENV_KWARGS.get(bare, {})
    for key, value in config.env_kwargs.items():
        if key not in allowed:
            raise ConfigError(
                f"{source}: env_kwargs: unknown key {brief(key)} for {bare}; allowed keys are "
                f"{', '.join(sorted(allowed)) or 'none'}"
            )
        types = allowed[key]
        if (isinstance(value, bool) and bool not in types) or not isinstance(value, types):
            raise ConfigError(f"{source}: env_kwargs.{key}: unexpected value {brief(value)}")
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"{source}: env_kwargs.{key}: expected a finite number")


def _constructor_keys(algo: str) -> set[str]:
    return set(inspect.signature(ALGORITHMS[algo].__init__).parameters) - {
        "self", "policy", "env", "seed", "tensorboard_log", "verbose", "_init_setup_model",
    }  # fmt: skip


def evaluation_targets(
    env_id: str, count: int, seed: int = 12345, env_kwargs: dict[str, Any] | None = None
) -> list[np.ndarray]:
    """A fixed set of targets drawn by the env's own sampler with a fixed seed."""
    env = gym.make(env_id, **(env_kwargs or {}))
    targets = []
    for i in range(count):
        _, info = env.reset(seed=seed + i)
        targets.append(np.asarray(info["target"], dtype=float))
    env.close()
    return targets


def _clearance(arm: Any) -> float:
    """The arm's surface clearance [cm].

    python-fcl where the env has a collision scene, else the numpy signed distance of its
    backbone samples (the FTL env's own contact test).
    """
    if hasattr(arm, "scene"):
        return float(arm.scene.check(arm.posture).clearance_cm)
    from aftir_rl.collision import point_clearance

    return float(point_clearance(arm.tank, arm.body()).min()) - arm.arm.radius


def evaluate_policy_on_targets(
    model: Any,
    env_id: str,
    targets: list[np.ndarray],
    clearance: bool = False,
    env_kwargs: dict[str, Any] | None = None,
) -> tuple[dict[str, float], dict[str, Any]]:
    """Run the deterministic policy once per target.

    Args:
        model: anything with SB3's ``predict``.
        env_id: the arm env.
        targets: evaluation targets [cm].
        clearance: also measure the smallest clearance along each motion (python-fcl distance
            at every step; slower).
        env_kwargs: keyword arguments of the env (the run's ``SB3Config.env_kwargs``).

    Returns:
        Means over targets (``success_rate``, ``tip_error_cm``, ``path_length_cm``,
        ``collision_rate``, ``seconds_per_target``, and ``min_clearance_cm``, the smallest over
        all motions, when asked) and the first episode's ``tips``, ``arm``, ``target`` and
        ``tank`` for a picture.

    """
    env = gym.make(env_id, **(env_kwargs or {}))
    arm: Any = env.unwrapped  # an arm env: tip, posture, scene, body(), tank
    rows, smallest, first = [], np.inf, {}
    for i, target in enumerate(targets):
        start = time.perf_counter()
        obs, info = env.reset(options={"target": target})
        tips, done = [arm.tip], False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(action)
            tips.append(arm.tip)
            if clearance:
                smallest = min(smallest, _clearance(arm))
            done = terminated or truncated
        path = np.array(tips)
        rows.append((
            float(info.get("is_success", False)), float(info["distance_cm"]),
            float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))),
            float(info.get("collision", False)), time.perf_counter() - start,
        ))  # fmt: skip
        if i == 0:
            first = {"tips": path, "target": target, "arm": arm.body(), "tank": arm.tank}
    env.close()
    mean = np.mean(np.array(rows), axis=0)
    keys = ("success_rate", "tip_error_cm", "path_length_cm", "collision_rate",
            "seconds_per_target")  # fmt: skip
    metrics = {k: float(v) for k, v in zip(keys, mean)}
    if clearance:
        metrics["min_clearance_cm"] = float(smallest)
    return metrics, first


class ArmEvalCallback(BaseCallback):
    """Evaluate on fixed targets every ``eval_freq`` environment steps and log the eval tags."""

    def __init__(
        self,
        env_id: str,
        targets: list[np.ndarray],
        eval_freq: int,
        env_kwargs: dict[str, Any] | None = None,
        on_evaluate: Any = None,
    ) -> None:
        super().__init__()
        self.env_id, self.targets, self.eval_freq = env_id, targets, eval_freq
        self.env_kwargs = dict(env_kwargs or {})
        self._next = eval_freq
        #: ``on_evaluate(model, metrics)`` after each evaluation is logged (a sweep's report).
        self.on_evaluate = on_evaluate

    def _init_callback(self) -> None:
        # A resumed model starts at its own step count: the next evaluation is the next multiple.
        self._next = (self.model.num_timesteps // self.eval_freq + 1) * self.eval_freq

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next += self.eval_freq
            self.evaluate()
        return True

    def _on_training_end(self) -> None:
        self.evaluate()

    def evaluate(self) -> dict[str, float]:
        """Run the evaluation now and log it."""
        from aftir_rl.plotting import render_path

        metrics, first = evaluate_policy_on_targets(
            self.model, self.env_id, self.targets, clearance=True, env_kwargs=self.env_kwargs
        )
        for key, value in metrics.items():
            self.logger.record(f"eval/{key}", value)
        picture = render_path(first["tank"], first["tips"], first["target"], arms=[first["arm"]],
                              title=f"{self.env_id}: evaluation target 1")  # fmt: skip
        self.logger.record("paths/eval", Image(picture, "HWC"),
                           exclude=("stdout", "log", "json", "csv"))  # fmt: skip
        self.logger.dump(self.num_timesteps)
        self.last_metrics = metrics
        if self.on_evaluate is not None:
            self.on_evaluate(self.model, metrics)
        return metrics


class AtomicCheckpoint(BaseCallback):
    """Save ``checkpoints/model_<steps>.zip`` every ``freq`` steps, atomically."""

    def __init__(self, directory: Path, freq: int) -> None:
        super().__init__()
        self.directory, self.freq = Path(directory), freq
        self._next = freq

    def _init_callback(self) -> None:
        # A resumed model starts at its own step count: the next checkpoint is the next multiple.
        self._next = (self.model.num_timesteps // self.freq + 1) * self.freq

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next += self.freq
            save_model(self.model, self.directory / f"model_{self.num_timesteps}.zip")
        return True


def save_model(model: BaseAlgorithm, path: Path) -> Path:
    """``model.save`` to a temporary file, then rename."""
    with atomic_open(path, "wb") as fh:
        model.save(cast(io.BufferedIOBase, fh))  # a binary file: an io.BufferedWriter
    return path


#: The most bytes a model archive may expand to (the arm envs' models are well under 10 MB).
MAX_MODEL_BYTES = 512_000_000

#: Counters read from a model's ``data`` (plain JSON integers); every other entry of ``data``,
#: pickled or not, is ignored: the model is built from our config and env.
_COUNTERS = ("num_timesteps", "_n_updates", "_episode_num")


#: What SB3's own pickled entries of ``data`` reference (spaces, schedules, buffers, policy
#: classes, numpy arrays). They are never unpickled; an entry that references anything else was
#: not written by SB3, and the file is refused.
_PICKLE_GLOBALS = {
    ("numpy", "dtype"), ("numpy", "ndarray"), ("numpy._core.numeric", "_frombuffer"),
    ("numpy.core.numeric", "_frombuffer"), ("numpy._core.multiarray", "_reconstruct"),
    ("numpy.core.multiarray", "_reconstruct"), ("numpy.random._pickle", "__generator_ctor"),
    ("numpy.random._pickle", "__bit_generator_ctor"), ("numpy.random._pcg64", "PCG64"),
    ("numpy.random.bit_generator", "__pyx_unpickle_SeedSequence"),
    ("numpy.random.bit_generator", "SeedSequence"), ("numpy.random._mt19937", "MT19937"),
    ("numpy.random._generator", "Generator"), ("numpy.random._pickle", "__randomstate_ctor"),
    ("numpy._core.multiarray", "scalar"), ("numpy.core.multiarray", "scalar"),
    ("collections", "deque"), ("collections", "OrderedDict"),
    ("stable_baselines3.common.utils", "FloatSchedule"),
    ("stable_baselines3.common.utils", "ConstantSchedule"),
    ("stable_baselines3.common.utils", "LinearSchedule"),
    ("stable_baselines3.common.type_aliases", "TrainFreq"),
    ("stable_baselines3.common.type_aliases", "TrainFrequencyUnit"),
}  # fmt: skip
_PICKLE_MODULES = (
    "gymnasium.spaces.", "stable_baselines3.common.policies", "stable_baselines3.common.buffers",
    "stable_baselines3.ppo.policies", "stable_baselines3.sac.policies",
    "stable_baselines3.td3.policies", "stable_baselines3.her.",
)  # fmt: skip


def _pickle_globals(raw: bytes) -> list[tuple[str, str]] | None:
    """The ``(module, name)`` pairs a pickle would import, read without running it.

    Simulates the pickle machine's stack with :mod:`pickletools` (opcodes only, nothing built);
    None when a global's name is not a literal string (then it cannot be told).
    """
    import pickletools

    unknown, mark = object(), object()
    stack: list[Any] = []
    memo: dict[int, Any] = {}
    found: list[tuple[str, str]] = []
    for op, arg, _ in pickletools.genops(raw):
        name = op.name
        if name in ("PUT", "BINPUT", "LONG_BINPUT", "MEMOIZE"):  # the stack is left as it is
            if stack:
                # typeshed: arg is Any | None; the PUT and GET opcodes always carry an int
                memo[len(memo) if name == "MEMOIZE" else int(cast(int, arg))] = stack[-1]
            continue
        if name in ("GLOBAL", "INST"):
            module, _, attr = str(arg).partition(" ")
            found.append((module, attr))
        elif name == "STACK_GLOBAL":
            if len(stack) < 2 or not all(isinstance(x, str) for x in stack[-2:]):
                return None
            found.append((stack[-2], stack[-1]))
        if any(x is pickletools.markobject for x in op.stack_before):
            while stack and stack[-1] is not mark:
                stack.pop()
            if stack:
                stack.pop()
        else:
            del stack[len(stack) - len(op.stack_before) :]
        for item in op.stack_after:
            if item is pickletools.markobject:
                stack.append(mark)
            elif isinstance(arg, str) and ("UNICODE" in name or "STRING" in name):
                stack.append(arg)
            elif name in ("GET", "BINGET", "LONG_BINGET"):
                stack.append(memo.get(int(cast(int, arg)), unknown))
            else:
                stack.append(unknown)
    return found


def _check_pickled_entries(data: dict[str, Any], path: Path) -> None:
    """Refuse a model whose ``data`` holds a pickled entry SB3 would not write (never decoded)."""
    import base64
    import binascii

    for key, item in data.items():
        if not (isinstance(item, dict) and ":serialized:" in item):
            continue
        try:
            raw = base64.b64decode(str(item[":serialized:"]).encode(), validate=True)
            found = _pickle_globals(raw)
        except (binascii.Error, ValueError, IndexError, TypeError):
            found = None
        bad = (
            None
            if found is None
            else [f"{m}.{n}" for m, n in found
                  if (m, n) not in _PICKLE_GLOBALS and not m.startswith(_PICKLE_MODULES)]
        )  # fmt: skip
        if found is None or bad:
            what = f"references {shorten(', '.join(bad), 80)}" if bad else "cannot be read"
            raise CheckpointError(
                f"{path}: data.{shorten(str(key), 40)} is a pickle that {what}, which SB3 does "
                "not write; refused without unpickling it"
            )


def newest_model(path: str | os.PathLike[str]) -> Path:
    """The model a path names: a ``.zip``, a run's ``model.zip``, or else its newest checkpoint.

    A run directory without ``model.zip`` (an interrupted run) gives its newest
    ``checkpoints/model_<steps>.zip``.

    Raises:
        CheckpointError: nothing to load there.

    """
    path = Path(path)
    if not path.is_dir():
        if not path.is_file():
            raise CheckpointError(
                f"{path}: no such model file; pass a run directory or a .zip model"
            )
        return path
    if (path / "model.zip").is_file():
        return path / "model.zip"
    steps = []
    for p in (path / "checkpoints").glob("model_*.zip"):
        tail = p.stem[len("model_") :]
        if tail.isdigit() and p.is_file():
            steps.append((int(tail), p))
    if not steps:
        raise CheckpointError(
            f"{path}: no model.zip and no checkpoints/model_<steps>.zip; pass a run directory "
            "of python -m aftir_rl.train ppo|sac|td3"
        )
    return max(steps)[1]


def build_model(
    algo: str, config: SB3Config, env: Any, seed: int | None = 0, evaluation: bool = False
) -> BaseAlgorithm:
    """A new model of ``algo`` for ``env`` from a checked ``config``.

    ``evaluation``: a one-transition replay buffer (off-policy algorithms), for a model only
    loaded to act.

    Raises:
        ConfigError: the algorithm refuses the hyperparameters.

    """
    hyper = dict(config.hyperparameters)
    if config.her and not evaluation:
        from stable_baselines3 import HerReplayBuffer

        hyper.update(replay_buffer_class=HerReplayBuffer, replay_buffer_kwargs=dict(HER_KWARGS))
    if evaluation and "buffer_size" in _constructor_keys(algo):
        hyper["buffer_size"] = 1
        hyper.pop("optimize_memory_usage", None)
    try:
        return ALGORITHMS[algo](config.policy, env, seed=seed, verbose=0, **hyper)
    except (ValueError, TypeError, AssertionError, KeyError) as exc:
        raise ConfigError(
            f"{algo.upper()} refuses these hyperparameters: {shorten(str(exc) or repr(exc), 200)}"
        ) from None


def _read_archive(
    path: Path, names: set[str], variables: set[str]
) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """``(data, state_dicts, variables)`` of an SB3 ``.zip`` without unpickling anything.

    ``data`` is parsed as JSON; SB3's base64 cloudpickle entries in it are never decoded. Tensors
    are read with ``torch.load(weights_only=True)``, which builds tensors and plain containers
    only; ``.pth`` files other than ``names`` (state dicts) and ``pytorch_variables.pth`` are
    refused.
    """
    import io
    import json
    import zipfile

    import torch

    try:
        with zipfile.ZipFile(path) as archive:
            infos = archive.infolist()
            if len(infos) > 64 or sum(i.file_size for i in infos) > MAX_MODEL_BYTES:
                raise CheckpointError(f"{path}: too large or too many files for an SB3 model")
            files = {i.filename for i in infos}
            if "data" not in files:
                raise CheckpointError(f"{path}: not an SB3 model (no data entry)")
            data = json.loads(archive.read("data").decode("utf-8"))
            if not isinstance(data, dict):
                raise CheckpointError(f"{path}: not an SB3 model (data is not a JSON object)")
            _check_pickled_entries(data, path)
            params, extra = {}, {}
            for name in sorted(files):
                if not name.endswith(".pth"):
                    continue
                key = name[: -len(".pth")]
                if key not in names and name != "pytorch_variables.pth":
                    raise CheckpointError(
                        f"{path}: holds {brief(name)}, which this algorithm does not save; refused"
                    )
                buffer = io.BytesIO(archive.read(name))
                try:
                    obj = torch.load(buffer, map_location="cpu", weights_only=True)
                except Exception as exc:  # UnpicklingError for anything but tensors
                    raise CheckpointError(
                        f"{path}: {name} holds more than tensors ({shorten(str(exc), 120)}); "
                        "refused without running it"
                    ) from None
                if name == "pytorch_variables.pth":
                    if not isinstance(obj, dict) or set(obj) - variables:
                        raise CheckpointError(f"{path}: unexpected pytorch_variables; refused")
                    extra = obj
                else:
                    params[key] = obj
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, RecursionError) as exc:
        if isinstance(exc, CheckpointError):
            raise
        raise CheckpointError(
            f"{path}: not a readable SB3 model ({type(exc).__name__}: {shorten(str(exc), 120)}); "
            "retrain or pass the right file"
        ) from None
    return data, params, extra


def load_model(
    algo: str,
    path: str | os.PathLike[str],
    env: Any = None,
    config: SB3Config | None = None,
    evaluation: bool | None = None,
) -> BaseAlgorithm:
    """Load a saved SB3 model without unpickling anything from the file.

    The model is built from ``config`` (default :class:`SB3Config`) and ``env`` (default: one
    instance of ``config.env_id``), so its spaces, policy class and schedules are ours; the file
    gives only the weights and optimizer states (``torch.load(weights_only=True)``) and the step
    counters (plain JSON). A file that needs anything more (pickled Python objects in its tensor
    files, entries this algorithm does not save, weights of another shape) is refused.

    Args:
        algo: ``ppo``, ``sac`` or ``td3``.
        path: a ``.zip``, or a run directory (``model.zip``, else its newest checkpoint).
        env: the (vector) env to attach; None: a new one, and a model only fit to act.
        config: the run's config (policy, hyperparameters, env id).
        evaluation: build a minimal replay buffer (default: when ``env`` is None).

    Raises:
        CheckpointError: saying what is wrong.

    """
    import torch

    from aftir_rl.safety import registered_env_id

    if algo not in ALGORITHMS:
        raise CheckpointError(
            f"unknown algorithm {brief(algo)}; use one of {', '.join(ALGORITHMS)}"
        )
    path = newest_model(path)
    config = config or SB3Config()
    if evaluation is None:
        evaluation = env is None
    if env is None:
        env_id = f"aftir_rl:{registered_env_id(config.env_id, 'config')}"
        env = gym.make(env_id, **dict(getattr(config, "env_kwargs", None) or {}))
    model = build_model(algo, config, env, seed=0, evaluation=evaluation)
    names, variables = model._get_torch_save_params()
    data, params, extra = _read_archive(path, set(names), set(variables))
    policy_kwargs = data.get("policy_kwargs", {})
    if isinstance(policy_kwargs, dict) and ":serialized:" in policy_kwargs:
        raise CheckpointError(
            f"{path}: its policy_kwargs are pickled Python objects, which are never loaded; refused"
        )
    hint = "load it with the config it was trained with (the run's config.json)"
    try:
        model.set_parameters(params, exact_match=True, device="cpu")
    except (RuntimeError, ValueError, KeyError, TypeError, IndexError, AttributeError) as exc:
        raise CheckpointError(
            f"{path}: its weights do not fit a {algo.upper()} {config.policy} on "
            f"{config.env_id} with these hyperparameters ({shorten(str(exc), 160)}); {hint}"
        ) from None
    for name, tensor in extra.items():
        if tensor is None:
            continue
        current: Any = model
        for part in name.split("."):
            current = getattr(current, part, None)
        if (not isinstance(tensor, torch.Tensor) or not isinstance(current, torch.Tensor)
                or tensor.shape != current.shape):  # fmt: skip
            raise CheckpointError(f"{path}: {name} does not fit this model; {hint}")
        current.data = tensor.data.to(current.dtype)
    for key in _COUNTERS:
        value = data.get(key, 0)
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 10**12:
            raise CheckpointError(f"{path}: data.{key} is not a step count; refused")
        if hasattr(model, key):
            setattr(model, key, value)
    return model


def load_run(run_dir: str | os.PathLike[str]) -> tuple[str, SB3Config, str, BaseAlgorithm]:
    """``(algo, config, env_id, model)`` of an SB3 run directory, nothing unpickled.

    ``config.json`` is read with a size limit and every key checked (:func:`sb3_config_from_run`);
    ``env_id`` is ``aftir_rl:<registered id>``; the model is ``model.zip``, or the newest
    checkpoint of an interrupted run (:func:`load_model`).

    Raises:
        CheckpointError: saying what is wrong.

    """
    from aftir_rl.safety import read_json, registered_env_id

    run_dir = Path(run_dir)
    source = str(run_dir / "config.json")
    algo, config = sb3_config_from_run(read_json(source, "config.json"), source)
    env_id = f"aftir_rl:{registered_env_id(config.env_id, source)}"
    return algo, config, env_id, load_model(algo, run_dir, config=config)
