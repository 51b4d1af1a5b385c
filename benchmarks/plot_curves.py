"""Success against wall time of training runs, one plot: the RL recipes side by side.

Run: ``python benchmarks/plot_curves.py LABEL=OFFSET_S=RUN_DIR [...] -o PNG [--json OUT]
[--merge JSON] [--route JSON]``.
Each run directory's ``progress.csv`` gives its periodic evaluations (``eval/success_rate``,
on the run's fixed evaluation targets) and the training time at each (``time/time_elapsed`` of
the last training row before it); ``OFFSET_S`` seconds are added to every time (what came before
the run: the dataset, the cloning, earlier stages). Runs that share a label are one method
(its seeds). ``--merge`` draws the curves of an earlier ``--json`` first (runs no longer on
this machine). ``--route`` adds the route policies of ``experiments/route_dagger.py``'s JSON:
each seed's last round at its training minutes, greedy and searched, on its held-out targets.
The plot marks the goal of 98% success in 15 minutes.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def curve(run: Path, offset: float) -> list[tuple[float, float]]:
    """``(minutes, success)`` of every evaluation in ``run/progress.csv``."""
    points, elapsed = [], None
    with (run / "progress.csv").open(newline="") as f:
        for row in csv.DictReader(f):
            if row.get("time/time_elapsed"):
                elapsed = float(row["time/time_elapsed"])
            if row.get("eval/success_rate") and elapsed is not None:
                points.append(((offset + elapsed) / 60, float(row["eval/success_rate"])))
    return points


def main() -> None:
    """Read the runs, draw the plot, write the points."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("runs", nargs="*", help="LABEL=OFFSET_S=RUN_DIR")
    parser.add_argument("-o", "--output", type=Path, required=True, help="the PNG to write")
    parser.add_argument("--json", type=Path, help="also write the points here")
    parser.add_argument("--merge", type=Path, help="an earlier --json whose curves come first")
    parser.add_argument("--route", type=Path, help="route policies (route_dagger.py's JSON)")
    args = parser.parse_args()
    curves: dict[str, list[list[tuple[float, float]]]] = {}
    runs = list(args.runs)
    if args.merge:
        earlier = json.loads(args.merge.read_text())
        curves = {
            label: [[tuple(p) for p in c] for c in cs] for label, cs in earlier["curves"].items()
        }
        runs = [*earlier["runs"], *runs]
    for spec in args.runs:
        label, offset, run = spec.split("=", 2)
        curves.setdefault(label, []).append(curve(Path(run), float(offset)))
    if args.route:
        data = json.loads(args.route.read_text())
        what = f"{data['recipe']} ({data['eval']['targets']} held-out targets)"
        searched = f"{data['eval']['budget']} steps of search"
        for key, how in (("greedy", "greedy"), ("search", searched)):
            label = f"{what}, {how}"
            for run in data["runs"]:
                last = run["rounds"][-1]
                curves.setdefault(label, []).append([(run["minutes"], last[key]["success"])])
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for (label, seeds), color in zip(curves.items(), colors):
        for k, points in enumerate(seeds):
            x, y = zip(*points) if points else ((), ())
            shown = label if k == 0 else None
            marker = "o" if len(points) == 1 else "."
            ax.plot(x, [100 * v for v in y], color=color, marker=marker, label=shown)
    ax.axhline(98, color="grey", linestyle="--", linewidth=1)
    ax.axvline(15, color="grey", linestyle=":", linewidth=1)
    ax.annotate("goal: 98% in 15 min", (15, 98), textcoords="offset points", xytext=(4, -12))
    ax.set(xlabel="wall time on 2 cores [min]", ylabel="success on the evaluation targets [%]",
           ylim=(0, 100), title="bay 2 (route policies: AFTIR-ArmRoute-v0)")  # fmt: skip
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(args.output)
    if args.json:
        args.json.write_text(json.dumps({"curves": curves, "runs": runs}, indent=1))
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
