"""Training runs, the library under ``python -m aftir_rl.train``.

- :mod:`aftir_rl.training.tabular`: Q-learning, one run per target or one for every target;
- :mod:`aftir_rl.training.sb3`: PPO, SAC, TD3 on the arm envs;
- :mod:`aftir_rl.training.common`: run names and the hyperparameters' text.
"""

from aftir_rl.training.sb3 import train_sb3
from aftir_rl.training.tabular import train_q_table, train_q_table_all_targets

__all__ = ["train_q_table", "train_q_table_all_targets", "train_sb3"]
