"""An RLlib run's policy as SB3's ``predict``, and its files read without unpickling.

An RLlib run keeps its weights and its learner's state as tensors only: ``rllib_module.pt``
(the module's ``state_dict``) and ``checkpoints/learner_<steps>.pt`` (module and optimizer
state, the form ``LearnerGroup.get_state`` gives, numpy arrays as tensors). Both are read by
:func:`aftir_rl.rl.tensors.load_tensors` (``torch.load(weights_only=True)``, size bounded):
nothing in a run directory runs code when it is read, unlike RLlib's own checkpoints (pickles).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aftir_rl.core.config import shorten
from aftir_rl.core.errors import CheckpointError

if TYPE_CHECKING:
    import gymnasium as gym

__all__ = ["MODULE_FILE", "RLlibPolicy", "learner_checkpoints"]

#: The weights of an RLlib run's policy (its RLModule's ``state_dict``).
MODULE_FILE = "rllib_module.pt"
_CHECKPOINT = re.compile(r"^learner_(\d{1,15})\.pt$")


def learner_checkpoints(run_dir: Path) -> list[tuple[int, Path]]:
    """``(steps, path)`` of a run's ``checkpoints/learner_<steps>.pt``, oldest first."""
    found = []
    for path in (Path(run_dir) / "checkpoints").glob("learner_*.pt"):
        match = _CHECKPOINT.match(path.name)
        if match and path.is_file():
            found.append((int(match.group(1)), path))
    return sorted(found)


class RLlibPolicy:
    """An RLlib module (PPO's or SAC's, inference only) with SB3's ``predict``.

    What evaluate, rollout and record call. The observation is flattened as RLlib's
    ``FlattenObservations`` connector does in training; the action is the distribution's mean
    (``deterministic``) or a sample (torch's generator), then mapped from RLlib's normalised
    actions into the action space, as the env runners do (``unsquash_action``).
    """

    def __init__(self, module: Any, space: gym.Space[Any], action_space: gym.Space[Any]) -> None:
        from ray.rllib.utils.spaces.space_utils import get_base_struct_from_space

        self.module, self.space, self.action_space = module, space, action_space
        self._struct = get_base_struct_from_space(space)
        self._dist = module.get_inference_action_dist_cls()

    def predict(self, observation: Any, *, deterministic: bool = True) -> tuple[Any, None]:
        """``(action, None)`` for one observation (SB3's signature)."""
        import torch
        from ray.rllib.core.columns import Columns
        from ray.rllib.utils.numpy import flatten_inputs_to_1d_tensor
        from ray.rllib.utils.spaces.space_utils import unsquash_action

        flat = flatten_inputs_to_1d_tensor(observation, self._struct, batch_axis=False)
        obs = torch.as_tensor(np.asarray(flat, dtype=np.float32))[None]
        with torch.no_grad():
            out = self.module.forward_inference({Columns.OBS: obs})
        dist = self._dist.from_logits(out[Columns.ACTION_DIST_INPUTS])
        if deterministic:
            dist = dist.to_deterministic()
        action = np.asarray(dist.sample()[0])
        return unsquash_action(action, self.action_space), None

    def acting(self, weights: dict[str, Any]) -> dict[str, Any]:
        """The tensors of a learner's module that this (inference-only) module has."""
        own = self.module.state_dict()
        return {k: v for k, v in weights.items() if k in own}

    def load_weights(self, weights: dict[str, Any], source: str) -> None:
        """Set the module's weights from a ``state_dict`` (every tensor, shapes as built).

        Raises:
            CheckpointError: a missing, unknown or misshapen tensor.

        """
        import torch

        own = self.module.state_dict()
        if not isinstance(weights, dict) or set(weights) != set(own):
            raise CheckpointError(f"{source}: not this run's network (its tensors differ)")
        for key, value in weights.items():
            if not isinstance(value, torch.Tensor) or value.shape != own[key].shape:
                raise CheckpointError(f"{source}: {shorten(key, 60)} has the wrong shape")
            if not torch.isfinite(value).all():
                raise CheckpointError(f"{source}: {shorten(key, 60)} is not finite")
        self.module.load_state_dict(weights)
