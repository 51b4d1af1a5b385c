"""``python -m aftir_rl.view``: see :mod:`aftir_rl.cli.view`."""

import sys

from aftir_rl.cli.view import main

if __name__ == "__main__":
    sys.exit(main())
