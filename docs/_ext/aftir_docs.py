"""Pages of the documentation generated from the package itself when Sphinx starts.

- ``envs/<id>.md`` for every id of :data:`aftir_rl.ENV_IDS`: the env's registration, its spaces
  as ``gym.make`` builds them, a picture from its ``rgb_array`` render (after a few random steps;
  the follow-the-leader env after the planner's motion),
  and its class docstring (description, spaces, rewards, episode end, arguments, version
  history), Gymnasium's layout.
- ``pretrained.md``: the policies shipped with the package, from their cards.
- ``cli.md``: one section per ``aftir`` subcommand of :data:`aftir_rl.cli.main.SUBCOMMANDS`, its
  options read from the subcommand's ``build_parser()`` by sphinx-argparse.

The generated files are not kept in git (``.gitignore``); each build writes them again.
"""

from __future__ import annotations

import inspect
import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import aftir_rl
from aftir_rl.cli.main import SUBCOMMANDS
from aftir_rl.envs.registration import REGISTRATIONS

ROLE = re.compile(r":(\w+):`([^`]+)`")


def _write(path: Path, text: str) -> None:
    """Write ``text`` unless the file already holds it (keeps Sphinx's incremental builds)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


def _entry_class(entry_point: str) -> Any:
    module, name = entry_point.split(":")
    return getattr(__import__(module, fromlist=[name]), name)


def _docstring(cls: Any) -> str:
    """The class docstring as MyST: RST roles become MyST roles; the summary line dropped."""
    doc = inspect.getdoc(cls) or ""
    body = doc.split("\n", 1)[1] if "\n" in doc else ""
    return ROLE.sub(r"{\1}`\2`", body).strip()


#: The follow-the-leader env's picture: the planner's motion to this bay-2 target, replayed.
STAGED_TARGET = (170.0, 80.0, 50.0)  # straight through the hatch


def _staged(env_id: str) -> tuple[Any, str]:
    """The env to draw, and its caption.

    After 20 random steps (seed 0); the follow-the-leader env after the expert's motion to
    :data:`STAGED_TARGET` (the arm through the hatch), the route env after the planner's
    choices to it (its online teacher's).
    """
    env = gym.make(env_id, render_mode="rgb_array")
    if env_id.startswith("AFTIR-ArmRoute-"):
        from aftir_rl.rl.route_policy import RouteTeacher

        teacher, route_env = RouteTeacher(), env.unwrapped
        env.reset(seed=0, options={"target": STAGED_TARGET})
        while (action := teacher(route_env)) is not None:
            _, _, terminated, _, _ = env.step(action)
            if terminated:
                break
        return env, f"after the planner's choices to {STAGED_TARGET} cm in bay 2"
    if env_id == "AFTIR-ArmFTL-v0":
        from aftir_rl.rl.expert import FTLExpert

        plan = FTLExpert().plan(STAGED_TARGET)
        if plan is not None:
            env.reset(seed=0, options={"target": STAGED_TARGET})
            for action in plan.actions:
                env.step(action)
            return env, f"after the planner's motion to {STAGED_TARGET} cm in bay 2"
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(20):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            break
    return env, "after 20 random steps"


def _picture(env_id: str, static: Path) -> tuple[str, str]:
    """Render the staged env into ``_static/envs/<id>.png``; its path and caption."""
    from PIL import Image

    env, caption = _staged(env_id)
    frame = np.asarray(env.render())
    env.close()
    out = static / "envs" / f"{env_id}.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(frame).save(out)
    return f"../_static/envs/{env_id}.png", caption


def _env_page(env_id: str, static: Path) -> str:
    spec: dict[str, Any] = REGISTRATIONS[env_id]
    cls = _entry_class(spec["entry_point"])
    env = gym.make(env_id)
    rows = [
        ("Import", f'`gym.make("aftir_rl:{env_id}")`'),
        ("Class", f"{{class}}`{cls.__module__}.{cls.__name__}`"),
        ("Action space", f"`{env.action_space}`"),
        ("Observation space", f"`{env.observation_space}`"),
        ("Registered keyword arguments", f"`{spec.get('kwargs', {})}`"),
        ("Truncation", f"{spec['max_episode_steps']} steps"),
    ]
    env.close()
    if "vector_entry_point" in spec:
        vector = (
            f'`gym.make_vec("aftir_rl:{env_id}", num_envs=B, '
            'vectorization_mode="vector_entry_point")`'
        )
        rows.append(("Vector env", vector))
    table = "\n".join(f"| {k} | {v} |" for k, v in rows)
    summary = (inspect.getdoc(cls) or "").split("\n", 1)[0]
    picture, caption = _picture(env_id, static)
    return (
        f"# `{env_id}`\n\n{summary}\n\n"
        f"![{env_id} {caption}]({picture})\n\n"
        f"| | |\n|---|---|\n{table}\n\n{_docstring(cls)}\n"
    )


def write_env_pages(docs: Path) -> None:
    """``envs/<id>.md`` and its picture for every registered id."""
    for env_id in aftir_rl.ENV_IDS:
        _write(docs / "envs" / f"{env_id}.md", _env_page(env_id, docs / "_static"))


def write_cli_page(docs: Path) -> None:
    """``cli.md``: every subcommand's options, from its parser."""
    parts = [
        "# The `aftir` command\n",
        "One command, one subcommand per tool (`python -m aftir_rl.<module>` works the same). "
        "The options below are read from each subcommand's parser when the site is built.\n",
    ]
    for name, (module, text) in SUBCOMMANDS.items():
        parts.append(
            f"## `aftir {name}`\n\n{text[0].upper()}{text[1:]}.\n\n"
            f"```{{argparse}}\n:module: {module}\n:func: build_parser\n:prog: aftir {name}\n"
            ":nodescription:\n```\n"
        )
    _write(docs / "cli.md", "\n".join(parts))


def write_pretrained_page(docs: Path) -> None:
    """``pretrained.md``: the policies shipped with the package, from their cards."""
    from aftir_rl.rl.pretrained import card, names

    rows = []
    for name in names():
        c = card(name)
        t, train = c["test"], c["training"]
        kwargs = ", ".join(f"`{k}={v}`" for k, v in c.get("env_kwargs", {}).items()) or "–"
        rows.append(
            f"| `{name}` | {c['algo'].upper()} | `{c['env_id']}` | {kwargs} | "
            f"{train['timesteps']:,} | {train['minutes']:.1f} | "
            f"{t['targets']} (seed {t['seed']}..) | {t['success_rate']:.1%} | "
            f"{t['tip_error_cm']:.2f} | {t['collision_rate']:.1%} |"
        )
    text = (
        "# Pretrained policies\n\n"
        "Trained policies shipped inside the package, by name. Each is a run directory read by the "
        "safe loader (nothing unpickled) with a card: the recipe, how it was chosen among the "
        "candidates (validation targets), and what it measured on held-out test targets that "
        "neither training nor the choice used. This table is generated from the cards "
        "(`benchmarks/pretrained_card.py` writes them; a slow test measures each card's check set "
        "again).\n\n"
        "```bash\naftir pretrained                 # the list\naftir pretrained NAME            "
        "# one card as JSON\naftir evaluate --pretrained NAME --random 200 --seed 4000000\n"
        "aftir rollout --pretrained NAME --target X Y Z -o DIR\n```\n\n"
        "```python\nimport gymnasium as gym\nfrom aftir_rl.rl.pretrained import load\n\n"
        'model, env_id, env_kwargs = load("ppo-armreach")\n'
        "env = gym.make(env_id, **env_kwargs)\n```"
        "\n\n| name | algorithm | env | env arguments | steps | training minutes | test targets "
        "| success | tip error (cm) | contacts |\n|---|---|---|---|---:|---:|---|---:|---:|---:|\n"
        + "\n".join(rows)
        + "\n\nSuccess is the deterministic policy's (its mean action). `aftir evaluate "
        "--pretrained NAME --random 200 --seed 4000000 --stochastic SEED` samples the actions "
        "instead; the [journal](experiments.md#the-mean-action-against-sampled-actions) "
        "compares the two.\n"
    )
    _write(docs / "pretrained.md", text + _route_policies())


def _route_policies() -> str:
    """The route policies shipped beside them (``aftir route plan --pretrained NAME``)."""
    from aftir_rl.cli.route import POLICY_FILE
    from aftir_rl.core.files import read_json
    from aftir_rl.rl.pretrained import POLICY_DIR

    rows = []
    for folder in sorted(p for p in POLICY_DIR.iterdir() if (p / POLICY_FILE).is_file()):
        c = read_json(folder / "card.json", "card")
        train, kwargs = c["training"], c["env_kwargs"]
        where = f"bay {kwargs['bay']}" if "bay" in kwargs else f"`tank={kwargs['tank']}`"
        corners = sum(c.get("corners", {}).values())
        keys = ("test", "test_wings", "test_round_wings", "test_b737")
        tests = [(k, c[k]) for k in keys if k in c]
        for i, (key, t) in enumerate(tests):
            tanks = {"test": where, "test_b737": "the 737 tank"}.get(key, f"`{t.get('tanks')}`")
            first = i == 0
            rows.append(
                (f"| `{c['name']}` | `{c['env_id']}` {where} | " if first else "| | | ")
                + (f"{train['routes']} routes, {train['rounds']} DAgger rounds | "
                   f"{train['minutes']:.1f} | " if first else "| | ")
                + f"{t['targets']} in {tanks} (seed {t['seed']}..) | "
                f"{t['greedy']['success_rate']:.1%} | "
                f"{t['search']['success_rate']:.1%} ({t['search']['budget']} env steps) | "
                f"{t['search']['min_clearance_cm']:.2f} | "
                + (f"{corners}/4 |" if first else "|")
            )  # fmt: skip
    return (
        "\n## Route policies\n\n"
        "Policies of `AFTIR-ArmRoute-v0` (the route planner's decision level), cloned from the "
        "planner's routes (`aftir route train`; the [journal](experiments.md#the-decision-level-"
        "a-route-section-at-a-time)), each with `card.json` beside its weights "
        "(`benchmarks/route_card.py` measures it). A success is a closed route whose whole "
        "motion keeps 1 cm (python-fcl); `aftir route plan --pretrained NAME --target X Y Z -o "
        "DIR` writes the motion as `trajectory.json`.\n\n"
        "| name | env | recipe | training minutes | test targets | greedy | searched | least "
        "clearance (cm) | reference corners |\n|---|---|---|---:|---|---:|---:|---:|---:|\n"
        + "\n".join(rows)
        + "\n"
    )


def _generate(app: Any) -> None:
    docs = Path(app.srcdir)
    write_env_pages(docs)
    write_cli_page(docs)
    write_pretrained_page(docs)


def setup(app: Any) -> dict[str, Any]:
    """Sphinx extension entry point."""
    app.connect("builder-inited", _generate)
    return {"parallel_read_safe": True, "version": "1"}
