"""``python -m aftir_rl.plan``: see :mod:`aftir_rl.cli.plan`."""

import sys

from aftir_rl.cli.plan import main

if __name__ == "__main__":
    sys.exit(main())
