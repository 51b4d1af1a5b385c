"""``python -m aftir_rl.train``: see :mod:`aftir_rl.cli.train`."""

import sys

from aftir_rl.cli.train import main

if __name__ == "__main__":
    sys.exit(main())
