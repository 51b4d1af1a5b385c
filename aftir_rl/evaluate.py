"""``python -m aftir_rl.evaluate``: see :mod:`aftir_rl.cli.evaluate`."""

import sys

from aftir_rl.cli.evaluate import main

if __name__ == "__main__":
    sys.exit(main())
