"""RLlib (Ray's distributed RL library) training the arm envs: ``aftir train ppo|sac --rllib``.

An optional extra (``pip install "aftir_rl[rllib]"``); nothing here imports Ray before a
function is called.

- :mod:`~aftir_rl.rl.rllib.config`: an SB3 PPO or SAC config as RLlib's, the same
  hyperparameters (:func:`rllib_config`), and the module a run's weights go into;
- :mod:`~aftir_rl.rl.rllib.train`: the run, on this machine or a Ray cluster
  (:func:`train_rllib`), and loading one for evaluation (:func:`load_rllib_run`);
- :mod:`~aftir_rl.rl.rllib.policy`: the module with SB3's ``predict`` (:class:`RLlibPolicy`),
  weights and learner state kept as tensors, read without unpickling.
"""

from aftir_rl.rl.rllib.config import check_rllib_config, ppo_config, rllib_config
from aftir_rl.rl.rllib.policy import MODULE_FILE, RLlibPolicy
from aftir_rl.rl.rllib.train import RLLIB_FILE, load_rllib_run, train_rllib

__all__ = [
    "MODULE_FILE",
    "RLLIB_FILE",
    "RLlibPolicy",
    "check_rllib_config",
    "load_rllib_run",
    "ppo_config",
    "rllib_config",
    "train_rllib",
]
