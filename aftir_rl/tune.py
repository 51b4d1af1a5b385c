"""``python -m aftir_rl.tune``: see :mod:`aftir_rl.cli.tune`."""

from aftir_rl.cli.guard import exit_with
from aftir_rl.cli.tune import main

if __name__ == "__main__":
    exit_with(main())
