"""aftir_rl: path planning for the AFTIR continuum robot in aircraft fuel tanks.

Importing the package registers its Gymnasium environments (see :data:`ENV_IDS`).
"""

from __future__ import annotations

import warnings

from aftir_rl.envs import ENV_IDS, register_envs

# `python -m aftir_rl.tank` runs a module that importing the package has already imported (the
# envs need the tank); runpy warns about that, harmlessly, on every run of the CLI.
warnings.filterwarnings(
    "ignore", message="'aftir_rl.tank' found in sys.modules", category=RuntimeWarning
)

__version__ = "0.1.0"
__all__ = ["ENV_IDS", "register_envs", "__version__"]

register_envs()
