"""Write ``docs/results.md`` from the benchmark scripts' JSON in ``benchmarks/results/``.

Run: ``python benchmarks/results_page.py [--results benchmarks/results] [-o docs/results.md]``.
Reads ``bench.json`` (``python -m aftir_rl.bench --json``: every method on the fixed target
sets), every ``seeds_*.json`` (``benchmarks/bench_seeds.py``: an RL recipe from several
seeds on the same held-out targets) and every ``route_*.json`` (``experiments/route_dagger.py``:
route policies from several seeds), every ``anytank_*.json`` (``experiments/route_anytank.py``:
a route policy taught on a stream of wings, in unseen tanks), and writes one page of tables and
the README's short table
(between its ``results`` markers); no number is typed by hand. ``--check`` exits 1 when either
differs from what the JSON gives.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

HEADER = """# Results

Every number on this page is read from the JSON the benchmark scripts wrote
(`benchmarks/results/`) by `python benchmarks/results_page.py`; rerun a script, then this, to
update it. The history of the runs that led to the shipped configs is in the
[experiments journal](experiments.md); the speed tables in [benchmarks](benchmarks.md).
"""


START, END = "<!-- results:start -->", "<!-- results:end -->"


def _num(value: Any, fmt: str) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return format(value, fmt)


def _machine(m: dict[str, Any]) -> str:
    threads = f", {m['torch_threads']} torch thread(s)" if "torch_threads" in m else ""
    cpu, cores, python = m.get("cpu", "?"), m.get("cores", "?"), m.get("python", "?")
    return f"{cpu}, {cores} cores{threads}, Python {python}, aftir_rl {m.get('aftir_rl', '?')}"


def bench_section(data: dict[str, Any]) -> str:
    """Every method on every fixed target set (``aftir bench``)."""
    o = data["options"]
    lines = [
        "## Every method on the fixed target sets\n",
        f"`python -m aftir_rl.bench --json benchmarks/results/bench.json`: sets "
        f"{', '.join(o['sets'])}; {o['n_random']} random targets per bay (seed {o['seed']}); "
        f"margin {o['margin']:g} cm. One run on {_machine(data['machine'])}; "
        f"{data['seconds'] / 60:.1f} minutes in all. What success means for each method: "
        "[the benchmark](reference.md#the-benchmark).\n",
        "| set | method | targets | success | median tip error (cm) | least clearance (cm) | "
        "median path (cm) | median s / target |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in data["rows"]:
        not_run = f" (+{r['not_run']} not run)" if r["not_run"] else ""
        lines.append(
            f"| {r['set']} | {r['method']} | {r['targets']}{not_run} | "
            f"{_num(r['success_rate'] * 100, '.0f')}% | {_num(r['tip_error_cm'], '.2g')} | "
            f"{_num(r['min_clearance_cm'], '.2f')} | {_num(r['path_cm'], '.0f')} | "
            f"{_num(r['seconds'], '.3f')} |"
        )
    return "\n".join(lines) + "\n"


def _task(d: dict[str, Any]) -> str:
    """The env and its bay, if the recipe names one."""
    bay = d["eval"].get("env_kwargs", {}).get("bay")
    return f"{d['env_id']}" + (f" bay {bay}" if bay else "")


def _clearance(runs: list[dict[str, Any]]) -> str:
    """The least clearance of the runs' motions, or "contact" (python-fcl reports -1)."""
    least = min(r["min_clearance_cm"] for r in runs)
    return "contact" if least < 0 else f"{least:.2f}"


def _pm(summary: dict[str, Any], key: str, scale: float, fmt: str) -> str:
    s = summary[key]
    return f"{format(s['mean'] * scale, fmt)} ± {format(s['std'] * scale, fmt)}"


def seeds_section(files: list[dict[str, Any]]) -> str:
    """One row per RL recipe: mean ± std over its seeds, then one row per seed."""
    lines = [
        "## RL recipes over seeds\n",
        "`python benchmarks/bench_seeds.py ALGO --config NAME --seeds ... --json ...`: each seed "
        "trains the recipe from scratch; its final model plays one deterministic episode per "
        "target on held-out targets its env draws (seeds training never evaluated on). Success: "
        "the tip within 2 cm without contact. Mean ± standard deviation over the seeds.\n",
        "| recipe | env | seeds | steps per seed | held-out targets | success (%) | "
        "tip error (cm) | contacts (%) | least clearance over seeds (cm) | minutes per seed |",
        "|---|---|---:|---:|---|---:|---:|---:|---:|---:|",
    ]
    for d in files:
        s, e = d["summary"], d["eval"]
        lines.append(
            f"| {d['recipe']} | {d['env_id']} | {len(d['runs'])} | "
            f"{s['timesteps']['mean']:,.0f} | {e['targets']} (seeds {e['seed']}..) | "
            f"{_pm(s, 'success_rate', 100, '.0f')} | {_pm(s, 'tip_error_cm', 1, '.1f')} | "
            f"{_pm(s, 'collision_rate', 100, '.0f')} | {_clearance(d['runs'])} | "
            f"{_pm(s, 'train_seconds', 1 / 60, '.1f')} |"
        )
    for d in files:
        made = (d.get("demos") or {}).get("made")
        if made:
            lines.append(
                f"\n{d['recipe']}: each seed first clones ({d['demos']['bc_epochs']} passes) "
                f"{made['episodes']} expert episodes ({made['steps']:,} steps; "
                f"{made['skipped']} targets without a motion skipped), written in the same run "
                f"from reset seed {made['seed']:,} in {made['seconds'] / 60:.1f} minutes by "
                f"{made['workers']} processes; the minutes per seed count the cloning, not the "
                "dataset."
            )
    lines += ["", "Each seed, and the machine it trained on:", ""]
    lines += [
        "| recipe | seed | steps | minutes | success | tip error (cm) | contacts | least "
        "clearance (cm) | machine | "
        "FrozenLake 8x8 steps/s (same run) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|",
    ]
    for d in files:
        for r in d["runs"]:
            lines.append(
                f"| {d['recipe']} | {r['seed']} | {r['timesteps']:,} | "
                f"{r['train_seconds'] / 60:.1f} | {r['success_rate']:.0%} | "
                f"{r['tip_error_cm']:.1f} | {r['collision_rate']:.0%} | {_clearance([r])} | "
                f"{_machine(d['machine'])} | {d['frozenlake_8x8_steps_per_s']:,.0f} |"
            )
    return "\n".join(lines) + "\n"


def _mean_std(values: list[float], scale: float, fmt: str) -> str:
    m = sum(values) / len(values)
    sd = math.sqrt(sum((v - m) ** 2 for v in values) / len(values))
    return f"{format(m * scale, fmt)} ± {format(sd * scale, fmt)}"


def _last(run: dict[str, Any]) -> dict[str, Any]:
    return run["rounds"][-1]


def route_section(files: list[dict[str, Any]]) -> str:
    """Route policies over seeds: greedy and searched success on the same held-out targets."""
    lines = [
        "## Route policies over seeds\n",
        "`python experiments/route_dagger.py --seeds 0 1 2 --bay B --json ...`: each seed clones "
        "a policy of the route env (the version each row names) from the planner's routes to its "
        "own training targets "
        "(the planner as the teacher: its queries are in the minutes), then plays each "
        "held-out target greedily, and best first within a budget of env steps. Success: a "
        "closed route whose whole motion keeps 1 cm (python-fcl). Mean ± standard deviation "
        "over the seeds.\n",
        "| recipe | bay | seeds | held-out targets | greedy (%) | searched (%) | search budget "
        "(env steps) | least clearance (cm) | reference corners | minutes per seed |",
        "|---|---:|---:|---|---:|---:|---:|---:|---|---:|",
    ]
    for d in files:
        runs, e = d["runs"], d["eval"]
        least = min(_last(r)["search"]["least_clearance_cm"] for r in runs)
        corners = [sum(_last(r).get("corners", [])) for r in runs]
        lines.append(
            f"| {d['recipe']}, `{d['env_id']}` | {d['bay']} | {len(runs)} | "
            f"{e['targets']} (seeds {e['seed']}..) "
            f"| {_mean_std([_last(r)['greedy']['success'] for r in runs], 100, '.1f')} | "
            f"{_mean_std([_last(r)['search']['success'] for r in runs], 100, '.1f')} | "
            f"{e['budget']} | {least:.2f} | "
            f"{', '.join(f'{c}/4' for c in corners) if d['bay'] == 2 else '–'} | "
            f"{_mean_std([r['minutes'] for r in runs], 1, '.1f')} |"
        )
    lines += ["", "Each seed, and the machine it trained on:", ""]
    lines += [
        "| recipe | bay | seed | minutes | labelled states | teacher queries (s) | greedy | "
        "searched | mean env steps searched | machine | FrozenLake 8x8 steps/s (same run) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|",
    ]
    for d in files:
        for r in d["runs"]:
            last = _last(r)
            t = last["teacher"]
            lines.append(
                f"| {d['recipe']} | {d['bay']} | {r['seed']} | {r['minutes']:.1f} | "
                f"{last['states']:,} | {t['queries']:,} ({t['seconds']:.0f}) | "
                f"{last['greedy']['success']:.1%} | {last['search']['success']:.1%} | "
                f"{last['search']['steps_mean']:.1f} | {_machine(d['machine'])} | "
                f"{d['frozenlake_8x8_steps_per_s']:,.0f} |"
            )
    return "\n".join(lines) + "\n"


def anytank_section(files: list[dict[str, Any]]) -> str:
    """One route policy for any tank: taught on a stream of wings, tested in unseen tanks."""
    lines = [
        "## One route policy for any tank\n",
        "`python experiments/route_anytank.py --seeds 0 1 --json ...`: each seed clones a policy "
        "of the route env (the version each table names) on its own stream of generated wings "
        "(the planner as the "
        "teacher; the recipe says which wings, and whether level replay chose some), then plays "
        "targets in tanks no training met: held-out 3-bay wings (default 20 with 10 targets "
        "each), held-out wings of the round family, the 737 tank (anywhere and per bay) and each "
        "scene of the suite, greedily and best first within each budget of env steps. Success: "
        "a closed route whose whole motion keeps 1 cm (python-fcl).\n",
    ]
    for d in files:
        b = d["budgets"]
        lines += [
            f"{d['recipe']} (`{d['env_id']}`); success in %, mean ± standard deviation over the "
            "seeds:\n",
            f"| tanks | targets | {' | '.join(['greedy', *(f'best first {k}' for k in b)])} | "
            "least clearance (cm) |",
            "|---|---:|" + "---:|" * (len(b) + 2),
        ]
        names = [
            k for k, v in d["runs"][0]["eval"].items() if isinstance(v, dict) and "targets" in v
        ]
        for name in names:
            rows = [r["eval"][name] for r in d["runs"]]
            rates = [
                _mean_std([row[key] for row in rows], 100, ".1f")
                for key in ["greedy", *(f"search_{k}" for k in b)]
            ]
            least = [row["least_clearance_cm"] for row in rows if row["least_clearance_cm"]]
            lines.append(
                f"| {name.replace('_', ' ')} | {rows[0]['targets']} | {' | '.join(rates)} | "
                f"{min(least):.2f} |"
            )
        lines += [
            "",
            "| seed | stream | wings met | replayed visits | minutes | labelled states | "
            "teacher queries (s) | machine | FrozenLake 8x8 steps/s (same run) |",
            "|---:|---|---:|---:|---:|---:|---:|---|---:|",
        ]
        for r in d["runs"]:
            t = r["teacher"]
            lines.append(
                f"| {r['seed']} | `{r['stream']}` | {r['wings_met']} | "
                f"{r.get('replayed_visits', 0)} | {r['minutes']:.1f} | "
                f"{r['states']:,} | {t['queries']:,} ({t['seconds']:.0f}) | "
                f"{_machine(d['machine'])} | {r['frozenlake_8x8_steps_per_s']:,.0f} |"
            )
        lines.append("")
    return "\n".join(lines)


#: What each benchmark method is, for the README's table.
METHODS = {
    "tsm": "a posture (three-segment method), no motion",
    "q_table+ftl": "Q-learning's cells, then a follow-the-leader motion (1 cm margin)",
    "q_table+postures": "the papers' chain of postures along the cells",
    "rrt_connect": "RRT-Connect in joint space (OMPL)",
}


def readme_table(results: Path) -> str:
    """The README's short table: the motion methods through the hatch, and each RL recipe."""
    lines = [
        "| method | task | success | time | runs |",
        "|---|---|---:|---:|---|",
    ]
    bench = results / "bench.json"
    if bench.exists():
        data = json.loads(bench.read_text())
        for r in data["rows"]:
            if r["set"] == "bay2":
                what = METHODS.get(r["method"], "")
                lines.append(
                    f"| `{r['method']}`: {what} | bay 2, {r['targets']} random targets | "
                    f"{_num(r['success_rate'] * 100, '.0f')}% | {_num(r['seconds'], '.2g')} s "
                    "per target | one run |"
                )
    for path in sorted(results.glob("seeds_*.json")):
        d = json.loads(path.read_text())
        s = d["summary"]
        lines.append(
            f"| {d['recipe']} | {_task(d)}, {d['eval']['targets']} held-out targets | "
            f"{_pm(s, 'success_rate', 100, '.0f')}% | "
            f"{_pm(s, 'train_seconds', 1 / 60, '.0f')} min training | {len(d['runs'])} seeds |"
        )
    for path in sorted(results.glob("route_*.json")):
        d = json.loads(path.read_text())
        runs = d["runs"]
        lines.append(
            f"| {d['recipe']}, searched within {d['eval']['budget']} env steps | "
            f"{d['env_id']} bay {d['bay']}, {d['eval']['targets']} held-out targets | "
            f"{_mean_std([_last(r)['search']['success'] for r in runs], 100, '.1f')}% "
            f"(greedy {_mean_std([_last(r)['greedy']['success'] for r in runs], 100, '.0f')}%) | "
            f"{_mean_std([r['minutes'] for r in runs], 1, '.1f')} min training | "
            f"{len(runs)} seeds |"
        )
    return "\n".join(lines)


def suite_section(data: dict) -> str:
    """The scene suite: per scene, completed motions, planning time and smallest clearance."""
    rows, m = data["rows"], data["machine"]
    lines = [
        "",
        "## Scene suite",
        "",
        f"`aftir bench --suite DIR --suite-targets 100` ({m['cpu']}, {m['cores']} cores, "
        f"{data['seconds']:.0f} s in all): the follow-the-leader planner with the 1 cm "
        "margin on each scene's fixed targets (seed = the scene's index; [tanks](tanks.md)). "
        "One run; every failure with its reason is in `benchmarks/results/suite/suite.json`.",
        "",
        "| scene | targets | complete | median s | p90 s | max s | smallest clearance (cm) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        mine = [r for r in rows if r["scene"] == scene]
        times = sorted(r["seconds"] for r in mine)
        clear = [r["min_clearance_cm"] for r in mine if r["complete"]]
        p90 = times[min(len(times) - 1, int(0.9 * len(times)))]
        lines.append(
            f"| {scene} | {len(mine)} | {sum(r['complete'] for r in mine)} | "
            f"{times[len(times) // 2]:.2f} | {p90:.2f} | {times[-1]:.2f} | "
            f"{_num(min(clear) if clear else None, '.2f')} |"
        )
    total = sum(r["complete"] for r in rows)
    lines += [
        "",
        f"In all {total} of {len(rows)} motions complete ({100 * total / len(rows):.1f}%).",
    ]
    missed = [r for r in rows if not r["complete"]]
    if missed:
        lines += ["", "The failures:", ""]
        for r in missed:
            where = ", ".join(f"{v:.1f}" for v in r["target"])
            lines.append(f"- {r['scene']} ({where}): {r['reason']}")
    return "\n".join(lines)


def with_readme_table(readme: str, table: str) -> str:
    """The README with the text between its results markers replaced by ``table``."""
    head, rest = readme.split(START, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{START}\n{table}\n{END}{tail}"


def render(results: Path) -> str:
    """The page's text from the JSON files in ``results``."""
    parts = [HEADER]
    bench = results / "bench.json"
    if bench.exists():
        parts.append(bench_section(json.loads(bench.read_text())))
    seeds = [json.loads(p.read_text()) for p in sorted(results.glob("seeds_*.json"))]
    if seeds:
        parts.append(seeds_section(seeds))
    routes = [json.loads(p.read_text()) for p in sorted(results.glob("route_*.json"))]
    if routes:
        parts.append(route_section(routes))
    anytank = [json.loads(p.read_text()) for p in sorted(results.glob("anytank_*.json"))]
    if anytank:
        parts.append(anytank_section(anytank))
    suite = results / "suite" / "suite.json"
    if suite.exists():
        parts.append(suite_section(json.loads(suite.read_text())))
    return "\n".join(parts)


def main() -> int:
    """Write (or ``--check``) the page."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    here = Path(__file__).resolve().parent
    parser.add_argument("--results", type=Path, default=here / "results")
    parser.add_argument("-o", "--output", type=Path, default=here.parent / "docs" / "results.md")
    parser.add_argument("--check", action="store_true", help="exit 1 if the page is stale")
    args = parser.parse_args()
    text = render(args.results)
    readme_path = here.parent / "README.md"
    readme = readme_path.read_text()
    new_readme = with_readme_table(readme, readme_table(args.results))
    if args.check:
        current = args.output.read_text() if args.output.exists() else ""
        if current != text or readme != new_readme:
            print(f"{args.output} or README.md is stale: run {sys.argv[0]}", file=sys.stderr)
            return 1
        return 0
    args.output.write_text(text)
    readme_path.write_text(new_readme)
    print(f"wrote {args.output} and README.md's results table")
    return 0


if __name__ == "__main__":
    sys.exit(main())
