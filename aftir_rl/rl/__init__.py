"""Learning agents: tabular Q-learning and the Stable-Baselines3 side.

:mod:`~aftir_rl.rl.tabular`: Q-tables, their training and checkpoints; :mod:`~aftir_rl.rl.sb3`:
configs, training, evaluation, safe loading, the vector adapter.
"""
