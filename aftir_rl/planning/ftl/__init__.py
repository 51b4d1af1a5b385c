"""Motions of the arm: follow-the-leader deployment along a route planned from the learned cells.

- :mod:`aftir_rl.planning.ftl.model`: the follow-the-leader (shift-and-copy) deployment model.
- :mod:`aftir_rl.planning.ftl.route`: a route an FTL arm can follow, from a learned cell path.
"""
