"""aftir_rl: path planning for the AFTIR continuum robot in aircraft fuel tanks.

Importing the package registers its Gymnasium environments (see :data:`ENV_IDS`) by string
entry points: nothing heavier than Gymnasium is imported until an env is made.
"""

from __future__ import annotations

import sys

if sys.argv[:1] == ["-m"]:  # ``python -m aftir_rl...`` is locating its module: Ctrl-C is one line
    from aftir_launch import take_signals

    take_signals()

from aftir_rl.envs.registration import ENV_IDS, register_envs

__version__ = "0.1.0"
__all__ = ["ENV_IDS", "register_envs", "__version__"]

register_envs()
