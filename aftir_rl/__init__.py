"""aftir_rl: path planning for the AFTIR continuum robot in aircraft fuel tanks.

Importing the package registers its Gymnasium environments (see :data:`ENV_IDS`).
"""

from __future__ import annotations

from aftir_rl.envs import ENV_IDS, register_envs

__version__ = "0.1.0"
__all__ = ["ENV_IDS", "register_envs", "__version__"]

register_envs()
