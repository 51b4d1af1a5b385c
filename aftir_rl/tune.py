"""``python -m aftir_rl.tune``: see :mod:`aftir_rl.cli.tune`."""

import sys

from aftir_rl.cli.tune import main

if __name__ == "__main__":
    sys.exit(main())
