"""``python -m aftir_rl.bench``: see :mod:`aftir_rl.cli.bench`."""

from aftir_rl.cli.bench import main
from aftir_rl.cli.guard import exit_with

if __name__ == "__main__":
    exit_with(main())
