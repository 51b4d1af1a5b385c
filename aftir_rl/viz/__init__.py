"""Pictures: matplotlib drawings of a tank and an arm, and the interactive 3D page of runs.

Draws what :mod:`aftir_rl.core` defines; the envs render through it.
"""
