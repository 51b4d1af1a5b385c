"""``aftir route train|plan``: route policies, taught by the planner, planning motions.

A thin command line over :mod:`aftir_rl.rl.route_policy` on ``AFTIR-ArmRoute-v1`` (the arm's
route decided a section at a time):

- ``aftir route train -o DIR``: clone a policy from the planner's routes to ``--routes``
  targets of the bay, then ``--rounds`` DAgger rounds; writes ``DIR/route_policy.pt`` (tensors
  only) and ``DIR/config.json`` (the options, the minutes, the teacher's queries). ``--tank``
  trains in another tank, a pool of wings or a stream of them (``--tank-episodes`` routes each);
- ``aftir route plan DIR --target X Y Z -o OUT``: the policy's route to each target (best first
  within ``--budget`` env steps), deployed and checked along its whole motion; writes
  ``OUT/<target>/trajectory.json`` (the planner's contract, timed: ``aftir view`` and ``aftir
  check`` read it) and ``summary.json``. ``--pretrained NAME`` takes a shipped route policy,
  ``--tank`` plans in any one tank (a policy trained on a pool or a stream needs it).

Neither replaces a file that is there: a policy or a target's motion already written is one
line and exit 2.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aftir_rl.cli.args import (
    OneLineParser,
    add_seed_option,
    add_tank_option,
    add_target_option,
    bounded_float,
    bounded_int,
    check_tank,
)
from aftir_rl.cli.guard import cli
from aftir_rl.core.errors import CheckpointError, ConfigError

if TYPE_CHECKING:
    from aftir_rl.envs.ftl.route_env import ArmRouteEnv
    from aftir_rl.rl.route_policy import RoutePolicy

__all__ = ["POLICY_FILE", "build_parser", "main", "route_policy_dir"]

#: The weights file of a route policy's folder (its options beside it in ``config.json``).
POLICY_FILE = "route_policy.pt"
#: The most targets one ``plan`` command takes.
MAX_TARGETS = 1000


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir route``."""
    parser = OneLineParser(
        prog="aftir route",
        description="Route policies on AFTIR-ArmRoute-v1: train one from the planner, plan "
        "motions with one, or evaluate one across tanks.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_train_parser(sub)
    _add_plan_parser(sub)
    _add_evaluate_parser(sub)
    return parser


def _add_train_parser(sub: Any) -> None:
    train = sub.add_parser(
        "train",
        help="clone a route policy from the planner's routes, then DAgger rounds",
        description="Clone a route policy from the planner's routes to --routes targets, then "
        "--rounds DAgger rounds (the policy's routes, labelled by the planner's continuation).",
    )
    train.add_argument("-o", "--output", required=True, metavar="DIR", help="the policy's folder")
    add_tank_option(train, "the tank the routes are in (default the reference tank)")
    train.add_argument(
        "--tank-episodes",
        type=bounded_int(1, 100_000),
        metavar="N",
        help="with a stream, routes in each wing (default the env's: 5)",
    )
    train.add_argument(
        "--replay",
        type=bounded_float(0.0, 1.0),
        metavar="P",
        help="with a stream, level replay: the probability that a wing's routes are in one met "
        "before, chosen by how much the policy has yet to learn there (PLR; default none)",
    )
    _add_bay_option(train)
    train.add_argument(
        "--routes",
        type=bounded_int(1, 100_000),
        default=600,
        metavar="N",
        help="training targets per round (default 600: about 2 minutes on 2 cores)",
    )
    train.add_argument(
        "--rounds", type=bounded_int(0, 100), default=0, metavar="R", help="DAgger rounds (0)"
    )
    train.add_argument(
        "--updates", type=bounded_int(1, 10**6), default=3000, metavar="U", help="batches per fit"
    )
    add_seed_option(train, "torch's seed and the training targets' (10,000,000 + 100,000 SEED..)")
    train.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def _add_policy_arguments(parser: argparse.ArgumentParser) -> None:
    """``DIR`` or ``--pretrained NAME``: the route policy a command uses."""
    parser.add_argument("policy", nargs="?", metavar="DIR", help="a folder aftir route train wrote")
    parser.add_argument(
        "--pretrained", metavar="NAME", help="a route policy shipped with the package instead"
    )


def _add_plan_parser(sub: Any) -> None:
    plan = sub.add_parser(
        "plan",
        help="a route policy's motions to targets, as trajectory.json",
        description="Plan motions with a route policy: its route to each target, searched best "
        "first within --budget env steps, deployed and checked along its whole motion.",
    )
    _add_policy_arguments(plan)
    plan.add_argument(
        "--tank",
        help="the tank to plan in: a name, YAML path or generator spec such as wing:3:7 "
        "(default the policy's own; needed where it was trained on a pool or a stream)",
    )
    _add_bay_option(plan, "the policy's")
    add_target_option(plan, "a target [cm] (repeatable)")
    plan.add_argument(
        "--random",
        type=bounded_int(1, MAX_TARGETS),
        metavar="N",
        help=f"N targets drawn in the policy's bay (1..{MAX_TARGETS}) instead of --target",
    )
    add_seed_option(plan, "first reset seed of --random (default 3000000)", 3_000_000)
    plan.add_argument(
        "--budget",
        type=bounded_int(0, 10_000),
        default=100,
        metavar="STEPS",
        help="env steps of the best-first search per target (0: greedy; default 100)",
    )
    plan.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")


def _add_evaluate_parser(sub: Any) -> None:
    ev = sub.add_parser(
        "evaluate",
        help="a route policy's success in tanks and pools, one row each, and every suite scene",
        description="Evaluate a route policy: --random targets in each --tank (a pool's spread "
        "over its tanks) and, with --suite, in each scene of aftir bench --suite (its own "
        "targets); greedily and best first within each --budget; one table.",
    )
    _add_policy_arguments(ev)
    ev.add_argument(
        "--tank",
        action="append",
        default=[],
        help="a tank, or a pool such as wing:3:900000-900019 (repeatable; default the policy's "
        "own tank and bay)",
    )
    _add_bay_option(ev, "the policy's in its own tank")
    ev.add_argument("--suite", action="store_true", help="also every scene of the scene suite")
    ev.add_argument(
        "--random",
        type=bounded_int(1, MAX_TARGETS),
        default=100,
        metavar="N",
        help=f"targets per row (1..{MAX_TARGETS}; default 100)",
    )
    add_seed_option(ev, "first reset seed of the targets (default 3000000)", 3_000_000)
    ev.add_argument(
        "--budget",
        type=bounded_int(1, 10_000),
        nargs="+",
        default=[100],
        metavar="STEPS",
        help="env steps of each best-first search per target (default 100); greedy is always run",
    )
    ev.add_argument("--json", metavar="FILE", help="also write the table as JSON")
    ev.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def _add_bay_option(parser: argparse.ArgumentParser, default: str = "2") -> None:
    parser.add_argument(
        "--bay",
        type=bounded_int(0, 99),
        metavar="N",
        help=f"the bay targets are drawn in, 0 for the whole tank (default {default} in the "
        "reference tank, else the whole tank)",
    )


def route_policy_dir(policy: str | None, pretrained: str | None) -> Path:
    """The folder of ``DIR`` or ``--pretrained NAME`` (one of them, not both)."""
    from aftir_rl.rl.pretrained import POLICY_DIR

    if (policy is None) == (pretrained is None):
        raise ConfigError("give a policy DIR or --pretrained NAME")
    if pretrained is None:
        return Path(str(policy))
    shipped = sorted(p.name for p in POLICY_DIR.iterdir() if (p / POLICY_FILE).is_file())
    if pretrained not in shipped:
        raise ConfigError(
            f"no shipped route policy named {pretrained[:80]!r}; shipped: {', '.join(shipped)}"
        )
    return POLICY_DIR / pretrained


def _train(args: argparse.Namespace) -> int:
    import torch
    from tqdm import tqdm

    from aftir_rl.core.files import check_output, check_writable_dir, write_json
    from aftir_rl.envs.ftl.pool import pool_specs, stream_spec
    from aftir_rl.envs.ftl.route_env import route_env
    from aftir_rl.envs.registration import ROUTE
    from aftir_rl.rl.level_replay import LevelReplay
    from aftir_rl.rl.route_policy import save_route_policy, train_route_policy

    for given, option in ((args.tank_episodes, "--tank-episodes"), (args.replay, "--replay")):
        if given is not None and stream_spec(args.tank) is None:
            raise ConfigError(f"{option} is a stream's: --tank wing:BAYS:FIRST+ or mix:FIRST+")
    if args.tank is not None:
        check_tank(args.tank)
    env_kwargs = _env_kwargs(args.tank, args.bay)
    if args.tank_episodes is not None:
        env_kwargs["tank_episodes"] = args.tank_episodes
    torch.set_num_threads(1)
    env = route_env(ROUTE, **env_kwargs)
    out = Path(args.output)
    for name in (POLICY_FILE, "config.json"):
        if check_output(out / name) is not None:
            raise ConfigError(f"{out / name}: exists; choose another --output")
    out = check_writable_dir(args.output, "--output")
    where = f"{args.tank or 'the reference tank'}, {_bay_words(env_kwargs.get('bay'))}"
    print(
        f"training on {args.routes} routes per round, {args.rounds} DAgger rounds "
        f"({where}, seed {args.seed})",
        flush=True,
    )
    bar = tqdm(total=args.routes * (args.rounds + 1), unit="route", disable=args.no_progress)

    def report(r: int, _: Any, row: dict[str, Any]) -> None:
        t = row["teacher"]
        bar.write(
            f"round {r}: {row['states']} labelled states, {row['train_accuracy']:.1%} fitted, "
            f"teacher {t['queries']} queries in {t['seconds']:.0f} s, {row['minutes']:.1f} min"
        )

    start = time.perf_counter()
    policy, stats = train_route_policy(
        env,
        routes=args.routes,
        rounds=args.rounds,
        updates=args.updates,
        seed=args.seed,
        first_target_seed=10_000_000 + 100_000 * args.seed,
        after_round=report,
        on_route=bar.update,
        level_replay=None if args.replay is None else LevelReplay(replay=args.replay),
    )
    bar.close()
    config = {
        "env_id": ROUTE,
        "env_kwargs": env_kwargs,
        "leads": list(env.leads),
        "max_change": env.settings.max_change,
        "routes": args.routes,
        "rounds": args.rounds,
        "updates": args.updates,
        "seed": args.seed,
        "replay": args.replay,
        "tanks_met": env.tanks_met or None,
        "minutes": round((time.perf_counter() - start) / 60, 2),
        "rows": stats.rounds,
    }
    save_route_policy(policy, out / POLICY_FILE)
    write_json(out / "config.json", config)
    many = args.tank is not None and (pool_specs(args.tank) or stream_spec(args.tank))
    where = " --tank TANK" if many else ""  # a pool's or stream's policy: which tank
    print(f"{out / POLICY_FILE}; aftir route plan {out}{where} --random 10 -o OUT plans with it")
    return 0


def _env_kwargs(tank: str | None, bay: int | None) -> dict[str, Any]:
    """The route env's arguments: ``tank`` (None: the reference tank) and its bay.

    ``bay`` None: bay 2 of the reference tank, the whole of any other; 0: the whole tank.
    """
    kwargs: dict[str, Any] = {} if tank is None else {"tank": tank}
    if bay is None:
        bay = 2 if tank is None else 0
    if bay:
        kwargs["bay"] = bay
    return kwargs


def _bay_words(bay: int | None) -> str:
    return f"bay {bay}" if bay else "the whole tank"


def _trained_on(folder: Path) -> dict[str, Any]:
    """What a policy's config says it was trained on: the env's version, a tank, a bay.

    The tank is a generated one or the reference; one the config names by path is not read
    (a shared folder cannot point at a file): ``plan --tank`` names it.
    """
    from aftir_rl.core.files import read_json
    from aftir_rl.core.tank.loading import names_generated
    from aftir_rl.envs.registration import ROUTE_IDS, registered_env_id

    config = read_json(folder / "config.json", "route policy config")
    where = f"{folder}/config.json"
    try:
        env_id = registered_env_id(
            config.get("env_id") if isinstance(config, dict) else None, where, ROUTE_IDS
        )
    except ConfigError:
        ids = ", ".join(ROUTE_IDS)
        raise CheckpointError(f"{where}: no env_id of a route env ({ids})") from None
    kwargs = config.get("env_kwargs") if isinstance(config, dict) else None
    if not isinstance(kwargs, dict) or not set(kwargs) <= {"tank", "bay", "tank_episodes"}:
        raise CheckpointError(f"{folder}/config.json: no env_kwargs of a route policy")
    bay, tank = kwargs.get("bay"), kwargs.get("tank")
    if bay is not None and (type(bay) is not int or not 1 <= bay <= 99):
        raise CheckpointError(f"{folder}/config.json: its bay is not 1 to 99")
    if tank is not None and not (isinstance(tank, str) and names_generated(tank)):
        tank = "a tank file"  # named by --tank
    return {"env_id": env_id, "tank": tank, "bay": bay}


def _name(target: Any) -> str:
    return "target_" + "_".join(f"{v:.1f}" for v in target)


def _plan_env(args: argparse.Namespace, folder: Path) -> tuple[Any, Any, dict[str, Any]]:
    """The env to plan in (``--tank`` and ``--bay``, else the policy's), the policy, its kwargs."""
    from aftir_rl.core.config import error_line
    from aftir_rl.envs.ftl.pool import pool_specs, stream_spec
    from aftir_rl.envs.ftl.route_env import route_env

    trained = _trained_on(folder)
    tank = args.tank if args.tank is not None else trained["tank"]
    if tank == "a tank file" or pool_specs(tank) is not None or stream_spec(tank) is not None:
        if args.tank is not None:
            raise ConfigError(f"--tank {tank}: names many tanks; give one tank, such as wing:3:7")
        raise ConfigError(f"{folder} was trained in {tank}: give --tank, the tank to plan in")
    if args.tank is not None:
        check_tank(args.tank)
    bay = args.bay if args.bay is not None else (trained["bay"] if args.tank is None else None)
    env_kwargs = _env_kwargs(tank, bay)
    try:
        env = route_env(trained["env_id"], **env_kwargs)
    except ConfigError as exc:  # a bay the config names that the tank does not have
        if args.tank is not None or args.bay is not None:
            raise
        raise CheckpointError(f"{folder}/config.json: {error_line(exc)}") from None
    return env, _loaded(folder, env), env_kwargs


def _loaded(folder: Path, env: ArmRouteEnv) -> RoutePolicy:
    """The policy of ``folder``, checked to read ``env``'s observation."""
    from aftir_rl.rl.route_policy import load_route_policy

    policy = load_route_policy(folder / POLICY_FILE)
    if policy.n_obs != env.n_obs:
        raise CheckpointError(f"{folder}: the policy reads {policy.n_obs} numbers, not {env.n_obs}")
    return policy


def _plan(args: argparse.Namespace) -> int:
    import numpy as np

    from aftir_rl.core.files import check_outputs, check_writable_dir, write_json
    from aftir_rl.core.shipped import DEFAULT_TANK
    from aftir_rl.core.tank import keep_run_tank
    from aftir_rl.planning.ftl.plan import MotionPlan
    from aftir_rl.rl.route_policy import route_search

    folder = route_policy_dir(args.policy, args.pretrained)
    if bool(args.target) == bool(args.random):
        raise ConfigError("give --target X Y Z (repeatable) or --random N")
    env, policy, env_kwargs = _plan_env(args, folder)
    jobs: list[tuple[int | None, Any]]
    if args.random:
        jobs = [(args.seed + i, None) for i in range(args.random)]
    else:
        jobs = [(None, np.array(t, dtype=np.float64)) for t in args.target]
    names = []  # each target drawn or checked by the env, its folder free: before any search
    for seed, target in jobs:
        env.inner.reset(seed=seed, options=None if target is None else {"target": target})
        names.append(_name(env.target))
    if len(set(names)) < len(names):
        raise ConfigError("a target is given twice (to 0.1 cm); each has one output folder")
    out = Path(args.output)
    for name in names:
        paths = [out / name / "trajectory.json", out / name / "summary.json"]
        check_outputs(paths, [folder])
        if any(p.exists() for p in paths):
            raise ConfigError(f"{out / name}: a motion is there already; choose another --output")
    out = check_writable_dir(args.output, "--output")
    reached = 0
    for (seed, target), name in zip(jobs, names, strict=True):
        start = time.perf_counter()
        result = route_search(env, policy, seed, args.budget, target)
        paths = [out / name / "trajectory.json", out / name / "summary.json"]
        plan = env.motion()
        if plan is None:
            arm = env.arm
            why = f"no route within {args.budget} env steps of the search"
            plan = MotionPlan(env.target, env.settings.margin, arm.section_length, False, 0.0)
            plan.reason = why
        plan.method, plan.seconds = "route-policy", time.perf_counter() - start
        (out / name).mkdir(exist_ok=True)
        write_json(paths[0], plan.to_json())
        summary = {
            "tank": keep_run_tank(env_kwargs.get("tank", DEFAULT_TANK), out / name),
            "method": "route-policy",
            "policy": args.pretrained or str(folder.resolve()),
            "bay": env_kwargs.get("bay"),
            "budget": args.budget,
            "steps": result.steps,
            "complete": result.success,
            "seed": seed,
        }
        write_json(paths[1], summary)
        reached += result.success
        clearance = f"clearance {plan.min_clearance_cm:.2f} cm, " if result.success else ""
        print(
            f"{name}: {'reached' if result.success else 'missed'}, {clearance}"
            f"{result.steps} env steps, {plan.seconds:.2f} s",
            flush=True,
        )
    print(f"{reached}/{len(jobs)} reached; aftir view {out}/<target> -o view.html shows one")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    import tempfile

    from tqdm import tqdm

    from aftir_rl.core.files import check_output, write_json
    from aftir_rl.core.shipped import DEFAULT_TANK
    from aftir_rl.envs.ftl.pool import pool_specs
    from aftir_rl.envs.ftl.route_env import route_env
    from aftir_rl.experiments.suite import SCENES, scene_tanks, suite_targets
    from aftir_rl.rl.route_policy import route_success

    folder = route_policy_dir(args.policy, args.pretrained)
    if args.json is not None and check_output(Path(args.json)) is not None:
        raise ConfigError(f"{args.json}: exists; choose another --json")
    rows: list[tuple[str, list[Any], list[Any]]] = []  # name, envs, jobs
    jobs = list(range(args.seed, args.seed + args.random))
    env_id = _trained_on(folder)["env_id"]  # the version the policy was taught in
    for tank in args.tank or [None]:
        specs = pool_specs(tank)
        if specs is None:  # one tank, checked as plan checks it (the policy's, if not given)
            env, policy, kwargs = _plan_env(argparse.Namespace(tank=tank, bay=args.bay), folder)
            envs = [env]
            tank = f"{kwargs.get('tank', DEFAULT_TANK)}, {_bay_words(kwargs.get('bay'))}"
        else:  # a pool: target i in its tank i·K/N
            check_tank(tank)
            envs = [route_env(env_id, **_env_kwargs(spec, args.bay)) for spec in specs]
        rows.append((tank, envs, jobs))
    policy = _loaded(folder, rows[0][1][0])  # every route env reads the same observation
    with tempfile.TemporaryDirectory() as scratch:
        if args.suite:
            for s, (name, tank) in enumerate(scene_tanks(Path(scratch)).items()):
                spec = SCENES[name] if isinstance(SCENES[name], str) else tank
                targets = list(suite_targets(tank, args.random, seed=s))
                rows.append((f"suite: {name}", [route_env(env_id, tank=spec)], targets))
        bar = tqdm(
            total=sum(len(jobs) for _, _, jobs in rows) * (1 + len(args.budget)),
            unit="search",
            disable=args.no_progress,
        )
        table = []
        for name, envs, jobs in rows:
            result = route_success(envs, policy, jobs, args.budget, on_search=bar.update)
            table.append({"tanks": name, **result})
        bar.close()
    heads = ["greedy", *(f"best first {b}" for b in args.budget)]
    print(f"| tanks | targets | {' | '.join(h + ' (%)' for h in heads)} | least clearance (cm) |")
    print("|---|---:|" + "---:|" * (len(heads) + 1))
    for row in table:
        rates = [row["greedy"], *(row[f"search_{b}"] for b in args.budget)]
        least = row["least_clearance_cm"]
        print(
            f"| {row['tanks']} | {row['targets']} | {' | '.join(f'{100 * r:.1f}' for r in rates)}"
            f" | {'-' if least is None else f'{least:.2f}'} |"
        )
    if args.json is not None:
        policy_name = args.pretrained or str(folder.resolve())
        write_json(Path(args.json), {"policy": policy_name, "budgets": args.budget, "rows": table})
    return 0


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir route``."""
    args = build_parser().parse_args(argv)
    run = {"train": _train, "plan": _plan, "evaluate": _evaluate}[args.command]
    return run(args)
