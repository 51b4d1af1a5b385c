"""Learning agents: tabular Q-learning and the Stable-Baselines3 side.

:mod:`~aftir_rl.rl.tabular`: Q-tables, their training and checkpoints; :mod:`~aftir_rl.rl.sb3`:
configs, training, evaluation, safe loading, the vector adapter; :mod:`~aftir_rl.rl.expert`,
:mod:`~aftir_rl.rl.demos` and :mod:`~aftir_rl.rl.imitation`: the follow-the-leader planner as
a teacher, its episodes as a dataset, behaviour cloning from them; :mod:`~aftir_rl.rl.pretrained`:
the trained policies shipped with the package.
"""
