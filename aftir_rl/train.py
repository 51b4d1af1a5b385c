"""``python -m aftir_rl.train``: see :mod:`aftir_rl.cli.train`."""

from aftir_rl.cli.guard import exit_with
from aftir_rl.cli.train import main

if __name__ == "__main__":
    exit_with(main())
