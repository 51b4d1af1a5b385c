"""The follow-the-leader arm env family (``AFTIR-ArmFTL-v0``): single and vector env.

``from aftir_rl.envs.ftl.env import ArmFTLEnv, ArmFTLVectorEnv``.
"""
