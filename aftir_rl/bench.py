"""``python -m aftir_rl.bench``: see :mod:`aftir_rl.cli.bench`."""

import sys

from aftir_rl.cli.bench import main

if __name__ == "__main__":
    sys.exit(main())
