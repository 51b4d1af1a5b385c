"""Planning: the papers' posture methods, joint-space moves and follow-the-leader motions.

:mod:`~aftir_rl.planning.posture` (one module per method), :mod:`~aftir_rl.planning.jointspace`
(straight joint-space moves and RRT-Connect) and :mod:`~aftir_rl.planning.ftl` (the
follow-the-leader model and its motion planner).
"""
