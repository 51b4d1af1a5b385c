"""Agents: tabular Q-learning (and, through the train CLI, SB3 baselines)."""

from aftir_rl.agents.q_table import QLearning, QLearningConfig, greedy_rollout

__all__ = ["QLearning", "QLearningConfig", "greedy_rollout"]
