"""``python -m aftir_rl.view``: see :mod:`aftir_rl.cli.view`."""

from aftir_rl.cli.guard import exit_with
from aftir_rl.cli.view import main

if __name__ == "__main__":
    exit_with(main())
