"""``python -m aftir_rl.evaluate``: see :mod:`aftir_rl.cli.evaluate`."""

from aftir_rl.cli.evaluate import main
from aftir_rl.cli.guard import exit_with

if __name__ == "__main__":
    exit_with(main())
