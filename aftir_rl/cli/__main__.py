"""``python -m aftir_rl.cli``: the ``aftir`` command (:mod:`aftir_rl.cli.main`)."""

from aftir_rl.cli.guard import exit_with
from aftir_rl.cli.main import main

if __name__ == "__main__":
    exit_with(main())
