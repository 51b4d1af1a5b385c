"""``python -m aftir_rl.cli``: the ``aftir`` command (:mod:`aftir_rl.cli.main`)."""

import sys

from aftir_rl.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
