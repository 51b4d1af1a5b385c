"""``aftir``: one command for every tool of the package, the way rl_zoo3 dispatches.

``aftir SUBCOMMAND [ARGS...]`` runs ``python -m aftir_rl.<module> [ARGS...]``; each subcommand
keeps its own ``--help``. Modules are imported only when their subcommand runs, so ``aftir plan``
and ``aftir tank`` start without torch.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

from aftir_rl.cli.guard import exit_with

__all__ = ["SUBCOMMANDS", "main"]

#: subcommand -> (module holding ``main(argv)``, one line of help)
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "train": (
        "aftir_rl.cli.train",
        "train q_table | ppo | sac | td3 (a run directory under runs/)",
    ),
    "plan": ("aftir_rl.cli.plan", "a checked posture for one target"),
    "tank": ("aftir_rl.cli.tank", "a tank's raster as z-slices, or its scene as JSON"),
    "evaluate": ("aftir_rl.cli.evaluate", "one table for trained runs of every kind"),
    "bench": ("aftir_rl.cli.bench", "every method on the same fixed target sets"),
    "view": ("aftir_rl.cli.view", "an interactive 3D HTML page of one or more runs"),
    "tune": ("aftir_rl.cli.tune", "a hyperparameter sweep on Ray Tune (needs aftir_rl[ray])"),
    "rollout": ("aftir_rl.cli.rollout", "a trained policy's motions as trajectory.json, for view"),
    "record": ("aftir_rl.cli.record", "a trained policy's episodes as an animated GIF"),
    "route": (
        "aftir_rl.cli.route",
        "route policies: train one from the planner, plan checked motions with one",
    ),
    "pretrained": (
        "aftir_rl.cli.pretrained",
        "the trained policies shipped with the package (--pretrained NAME)",
    ),
    "dataset": (
        "aftir_rl.cli.dataset",
        "expert episodes of AFTIR-ArmFTL-v0 as a Minari dataset (needs aftir_rl[demos])",
    ),
    "export": (
        "aftir_rl.cli.export",
        "a timed motion as ROS JointTrajectory JSON or CSV (needs aftir_rl[robot])",
    ),
    "tour": (
        "aftir_rl.cli.tour",
        "one timed deployment that visits many targets (needs aftir_rl[robot])",
    ),
    "check": ("aftir_rl.cli.check", "re-check a timed motion: time, limits, clearance; exit 0/1"),
    "simulate": (
        "aftir_rl.cli.simulate",
        "re-run a timed motion on a Cosserat rod under gravity (needs aftir_rl[physics])",
    ),
    "runs": ("aftir_rl.cli.runs", "the runs under a folder, unfinished ones too; remove old ones"),
    "configs": (
        "aftir_rl.cli.configs",
        "the shipped configs and tanks, by the names --config takes",
    ),
}


def _usage() -> str:
    width = max(map(len, SUBCOMMANDS))
    rows = "\n".join(f"  {name:<{width}}  {text}" for name, (_, text) in SUBCOMMANDS.items())
    return (
        "usage: aftir SUBCOMMAND [ARGS...]\n\n"
        "Path planning for the AFTIR continuum robot in aircraft fuel tanks.\n\n"
        f"subcommands:\n{rows}\n\n"
        "`aftir SUBCOMMAND --help` lists a subcommand's options; "
        "`python -m aftir_rl.<module>` works the same."
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``aftir`` console script."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(_usage())
        return 0
    if args[0] == "--version":
        from aftir_rl import __version__

        print(f"aftir_rl {__version__}")
        return 0
    name, rest = args[0], args[1:]
    if name not in SUBCOMMANDS:
        print(
            f"error: unknown subcommand {name!r}: choose one of {', '.join(SUBCOMMANDS)} "
            "(aftir --help)",
            file=sys.stderr,
        )
        return 2
    module = importlib.import_module(SUBCOMMANDS[name][0])
    prog = sys.argv[0] if argv is None else "aftir"
    sys.argv = [f"{prog} {name}", *rest]
    return int(module.main(rest) or 0)


if __name__ == "__main__":
    exit_with(main())
