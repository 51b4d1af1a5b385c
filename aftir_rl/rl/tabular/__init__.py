"""Tabular Q-learning: one target (:class:`QLearning`) or all at once (:class:`GoalQLearning`)."""

from aftir_rl.rl.tabular.q_table import QLearning, QLearningConfig, greedy_rollout
from aftir_rl.rl.tabular.q_table_goal import GoalQLearning, train_all_targets

__all__ = ["QLearning", "QLearningConfig", "greedy_rollout", "GoalQLearning", "train_all_targets"]
