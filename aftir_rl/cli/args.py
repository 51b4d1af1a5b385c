"""Options shared by the command lines, and the one parser class every command line uses.

:class:`OneLineParser` makes every error of a command line one line and exit status 2 (through
:func:`aftir_rl.cli.guard.cli`). Each ``add_*_option`` adds one option with the same flag, type,
metavar and checks in every command that has it (the help text is the command's own);
:func:`bounded_int` and :func:`coordinate` are ``type=`` functions that refuse a number outside
its bounds, naming them.
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable
from typing import NoReturn

from aftir_rl.core.config import DEFAULT_MARGIN, shorten
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.tank.loading import MAX_COORD, MAX_TARGETS

__all__ = [
    "MAX_EPISODES",
    "MAX_ENVS",
    "MAX_SEED",
    "MAX_TIMESTEPS",
    "MAX_WORKERS",
    "CommandLineError",
    "OneLineParser",
    "add_int_option",
    "add_key_values_option",
    "add_margin_option",
    "add_motion_option",
    "add_ray_options",
    "add_run_dir_options",
    "add_seconds_option",
    "add_seed_option",
    "add_target_option",
    "bounded_int",
    "check_margin",
    "coordinate",
]

#: The largest seed (numpy's and SB3's seeds are 32-bit).
MAX_SEED = 2**32 - 1
#: The most CPUs of ``--ray local`` (``--workers``).
MAX_WORKERS = 1024
#: The most training steps of a run or a trial (the largest ``total_timesteps`` of a config).
MAX_TIMESTEPS = 10**9
#: The most envs of a run (64 subprocesses, or 4,096 rows of a batched env: the config says).
MAX_ENVS = 4096
#: The most Q-learning episodes per target (``--episodes``).
MAX_EPISODES = 10**6

# argparse takes "-1e3" or "-inf" for an option (it knows only "-1" and "-1.5" as numbers)
_NEGATIVE_NUMBER = re.compile(
    r"^-(\d[\d_]*\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.IGNORECASE
)


class CommandLineError(ConfigError):
    """A command line its parser refuses: one line, ``error: ... (see --help)``, and status 2."""


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are :class:`CommandLineError`, not a usage block.

    The ``main`` of a command line is wrapped in :func:`aftir_rl.cli.guard.cli`, which prints the
    error as one line and returns 2 (the usage is left to ``--help``). A ``type=`` function's
    "must be ..." reads "--flag must be ...". Negative numbers such as ``-1e3`` and ``-inf`` are
    values, not options.
    """

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str) -> NoReturn:
        """Raise ``message`` as a :class:`CommandLineError` (one line, status 2 from ``cli``)."""
        message = re.sub(r"^argument (\S+): must be", r"\1 must be", message)
        raise CommandLineError(shorten(f"{message} (see --help)"))


def bounded_int(lo: int, hi: int) -> Callable[[str], int]:
    """A ``type=`` function: an integer from ``lo`` to ``hi`` ("1e6" is read as 1000000).

    Its error reads "must be from LO to HI, got VALUE".
    """

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
            try:
                number = float(text)
                value = int(number) if number.is_integer() else None
            except (ValueError, OverflowError):
                pass
        if value is None or not lo <= value <= hi:
            raise argparse.ArgumentTypeError(
                f"must be {'' if value is not None else 'an integer '}from {lo:,} to {hi:,}, "
                f"got {shorten(text, 40)}"
            )
        return value

    parse.__name__ = f"integer from {lo} to {hi}"
    return parse


def coordinate(text: str) -> float:
    """A ``type=`` function: a finite coordinate in cm, at most the tanks' ``MAX_COORD``."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and abs(value) <= MAX_COORD):
        raise argparse.ArgumentTypeError(
            f"must be finite numbers of at most {MAX_COORD:,g} cm in magnitude, got "
            f"{shorten(text, 40)}"
        )
    return value


class _AppendTarget(argparse.Action):
    """``append``, at most the tanks' ``MAX_TARGETS`` times."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: object,
        values: object,
        option_string: str | None = None,
    ) -> None:
        targets = list(getattr(namespace, self.dest, None) or [])
        if len(targets) >= MAX_TARGETS:
            parser.error(f"--target may be given at most {MAX_TARGETS:,} times")
        setattr(namespace, self.dest, [*targets, values])


def add_target_option(parser: argparse.ArgumentParser, help: str, required: bool = False) -> None:
    """``--target X Y Z`` in cm, repeatable (one ``--target`` with ``required``)."""
    parser.add_argument(
        "--target",
        nargs=3,
        type=coordinate,
        required=required,
        action="store" if required else _AppendTarget,
        metavar=("X", "Y", "Z"),
        help=help,
    )


def add_int_option(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    flag: str,
    bounds: tuple[int, int],
    help: str,
    default: int | None = None,
    metavar: str = "N",
) -> None:
    """``flag N``, an integer within ``bounds`` (both included; :func:`bounded_int`)."""
    parser.add_argument(
        flag, type=bounded_int(*bounds), default=default, metavar=metavar, help=help
    )


def add_seed_option(parser: argparse.ArgumentParser, help: str, default: int | None = 0) -> None:
    """``--seed SEED``, 0 to :data:`MAX_SEED`."""
    add_int_option(parser, "--seed", (0, MAX_SEED), help, default, metavar="SEED")


#: The largest ``--stochastic`` seed: target ``i`` of up to 10,000 is seeded ``SEED + i``.
MAX_POLICY_SEED = MAX_SEED - 10_000


def add_stochastic_option(parser: argparse.ArgumentParser, what: str) -> None:
    """``--stochastic [SEED]``: sampled actions, target ``i``'s episode seeded ``SEED + i``."""
    parser.add_argument(
        "--stochastic",
        nargs="?",
        const=0,
        type=bounded_int(0, MAX_POLICY_SEED),
        metavar="SEED",
        help=f"{what}: sample the policy's actions (RL Zoo's --stochastic) instead of taking "
        "its mean; target i's episode seeded SEED + i (default 0)",
    )


#: The largest time budget a ``--*-seconds`` flag takes [s]: an hour.
MAX_SECONDS = 3600.0


def bounded_float(lo: float, hi: float) -> Callable[[str], float]:
    """A ``type=`` function: a number from ``lo`` to ``hi`` (never NaN or infinite).

    Its error reads "must be from LO to HI, got VALUE".
    """

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(
                f"must be from {lo:g} to {hi:g}, got {shorten(text, 40)}"
            )
        return value

    return parse


def add_seconds_option(
    parser: argparse.ArgumentParser, flag: str, default: float, help: str
) -> None:
    """``flag S``, a time budget in seconds, from 0 to :data:`MAX_SECONDS`."""
    parser.add_argument(
        flag, type=bounded_float(0.0, MAX_SECONDS), default=default, metavar="S", help=help
    )


def add_key_values_option(parser: argparse.ArgumentParser, flag: str, help: str) -> None:
    """``flag KEY:VALUE ...``, RL Zoo's spelling of keyword arguments (values read as YAML)."""
    parser.add_argument(flag, nargs="+", default=[], metavar="KEY:VALUE", help=help)


def add_motion_option(parser: argparse.ArgumentParser, help: str) -> None:
    """``--motion ftl|progressive``: how a Q-table run's cells become a motion (default ftl)."""
    parser.add_argument("--motion", choices=("ftl", "progressive"), default="ftl", help=help)


def add_run_dir_options(parser: argparse.ArgumentParser, logdir_help: str, resume: str) -> None:
    """``--logdir`` (default ``runs``), ``--resume`` (from ``resume``) and ``--no-progress``."""
    parser.add_argument("--logdir", default="runs", help=logdir_help)
    parser.add_argument("--resume", help=f"{resume} or run directory to continue training from")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def add_margin_option(parser: argparse.ArgumentParser, help: str) -> None:
    """``--margin CM``, the clearance the arm keeps (default :data:`DEFAULT_MARGIN`)."""
    parser.add_argument("--margin", type=float, default=DEFAULT_MARGIN, metavar="CM", help=help)


def add_tank_option(parser: argparse.ArgumentParser, what: str) -> None:
    """Add ``--tank`` (a name, YAML path, generator spec or pool; :func:`check_tank`)."""
    parser.add_argument(
        "--tank",
        help=f"{what}: a name, YAML path, generator spec such as wing:3:7, a pool "
        "wing:BAYS:FIRST-LAST of generated tanks (one per group of rows, or per episode), or "
        "to train on, a stream wing:BAYS:FIRST+ (a new wing per group every tank_episodes)",
    )


def check_tank(tank: str) -> None:
    """One line (:class:`ConfigError`) unless ``tank`` loads (a pool's or stream's first)."""
    from aftir_rl.core.tank import load_tank
    from aftir_rl.envs.ftl.pool import pool_specs, stream_spec

    stream, specs = stream_spec(tank), pool_specs(tank)
    if stream is not None:
        tank = stream.spec_at(0)
    load_tank(tank if specs is None else specs[0])


def check_margin(margin: float) -> None:
    """Refuse a ``--margin`` outside 0 to 20 cm (a :class:`ConfigError`)."""
    if not 0 <= margin <= 20:
        raise ConfigError(f"--margin must be between 0 and 20 cm, got {margin}")


def add_ray_options(parser: argparse.ArgumentParser, what: str, default: str | None = None) -> None:
    """``--ray ADDRESS`` (``default``) and ``--workers N``: ``what`` (e.g. "evaluate the runs")."""
    parser.add_argument(
        "--ray",
        default=default,
        metavar="ADDRESS",
        help=f"{what} as Ray tasks: local (a Ray on this machine), auto or HOST:PORT (a "
        "cluster started with ray start); needs aftir_rl[ray]"
        + (f" (default {default})" if default else ""),
    )
    parser.add_argument(
        "--workers",
        type=bounded_int(1, MAX_WORKERS),
        metavar="N",
        help=f"CPUs of --ray local, 1 to {MAX_WORKERS} (default: every core)",
    )
