"""``python -m aftir_rl.plan``: see :mod:`aftir_rl.cli.plan`."""

from aftir_rl.cli.guard import exit_with
from aftir_rl.cli.plan import main

if __name__ == "__main__":
    exit_with(main())
