"""``python -m aftir_rl.tank``: see :mod:`aftir_rl.tank.cli`."""

import sys

from aftir_rl.tank.cli import main

if __name__ == "__main__":
    sys.exit(main())
