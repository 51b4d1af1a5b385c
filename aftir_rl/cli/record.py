"""``aftir record RUN_DIR --target X Y Z -o arm.gif``: a policy's episode as an animated picture.

A thin command line over :func:`aftir_rl.experiments.rollout.record_frames`: the env's
``rgb_array`` frames of one episode per target (``--stochastic``: sampled actions), written
as one GIF (Pillow), every ``--every``-th frame, with a progress bar.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from tqdm import tqdm

from aftir_rl.cli.args import bounded_int
from aftir_rl.cli.guard import cli
from aftir_rl.cli.rollout import (
    policy_env_kwargs,
    policy_parser,
    policy_run,
    policy_seed,
    policy_targets,
)
from aftir_rl.core.errors import ConfigError

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir record``."""
    parser = policy_parser(
        "aftir record", "Record an SB3 or RLlib run's policy going to targets as a GIF."
    )
    parser.add_argument("-o", "--output", required=True, metavar="FILE.gif", help="the GIF")
    parser.add_argument(
        "--every",
        type=bounded_int(1, 100),
        default=2,
        metavar="K",
        help="keep every K-th frame (default 2)",
    )
    parser.add_argument("--fps", type=bounded_int(1, 60), default=20, help="frames per second")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return parser


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir record``."""
    from aftir_rl.core.files import check_outputs
    from aftir_rl.experiments.rollout import record_frames
    from aftir_rl.experiments.runs import load_policy_run
    from aftir_rl.viz.plotting import save_gif

    args = build_parser().parse_args(argv)
    if not args.output.lower().endswith(".gif"):
        raise ConfigError(f"-o {args.output}: write a .gif")
    run = policy_run(args)
    check_outputs([args.output], [run])
    loaded = load_policy_run(run)
    config, env_id, model = loaded.config, loaded.env_id, loaded.model
    env_kwargs = policy_env_kwargs(args, config.env_kwargs)
    frames = []
    targets = policy_targets(args, env_id, env_kwargs)
    for i, target in enumerate(tqdm(targets, desc="episodes", disable=args.no_progress)):
        episode = record_frames(model, env_id, env_kwargs, target, policy_seed(args, i))
        frames += episode[:: args.every] + [episode[-1]] * 10  # hold the end a moment
    count = save_gif(args.output, frames, args.fps)
    print(f"wrote {args.output} ({count} frames)")
    return 0
