"""``python -m aftir_rl.tank``: the tank command line (:mod:`aftir_rl.cli.tank`).

The tank model itself is :mod:`aftir_rl.core.tank`.
"""
