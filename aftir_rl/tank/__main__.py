"""``python -m aftir_rl.tank``: see :mod:`aftir_rl.cli.tank`."""

import sys

from aftir_rl.cli.tank import main

if __name__ == "__main__":
    sys.exit(main())
