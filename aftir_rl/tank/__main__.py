"""``python -m aftir_rl.tank``: see :mod:`aftir_rl.cli.tank`."""

from aftir_rl.cli.guard import exit_with
from aftir_rl.cli.tank import main

if __name__ == "__main__":
    exit_with(main())
