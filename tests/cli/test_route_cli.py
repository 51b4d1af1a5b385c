"""``aftir route train|plan``: a route policy trained from the planner, its motions checked."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aftir_rl.cli import check, route, view

HATCH = ["--target", "170", "80", "50"]  # straight through the hatch


@pytest.fixture(scope="module")
def policy_dir(tmp_path_factory):
    """A policy cloned from the planner's routes to 4 bay-2 targets (about a second)."""
    out = tmp_path_factory.mktemp("route") / "policy"
    argv = ["train", "-o", str(out), "--routes", "4", "--updates", "100", "--seed", "3"]
    argv += ["--no-progress"]
    assert route.main(argv) == 0
    return out


def test_train_writes_the_policy_and_its_config_and_never_replaces_them(policy_dir, capsys):
    config = json.loads((policy_dir / "config.json").read_text())
    assert config["env_id"] == "AFTIR-ArmRoute-v1" and config["env_kwargs"] == {"bay": 2}
    assert config["leads"][:2] == [-40.0, -30.0] and config["max_change"] == 1.0
    assert config["routes"] == 4 and config["rows"][0]["states"] > 4
    before = (policy_dir / route.POLICY_FILE).read_bytes()
    capsys.readouterr()
    assert route.main(["train", "-o", str(policy_dir), "--routes", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "exists; choose another --output" in err
    assert (policy_dir / route.POLICY_FILE).read_bytes() == before


def test_plan_writes_a_timed_motion_that_check_and_view_read(policy_dir, tmp_path, capsys):
    out = tmp_path / "motions"
    argv = ["plan", str(policy_dir), *HATCH, "--budget", "300", "-o", str(out)]
    assert route.main(argv) == 0
    printed = capsys.readouterr().out
    folder = out / "target_170.0_80.0_50.0"
    data = json.loads((folder / "trajectory.json").read_text())
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["method"] == data["method"] == "route-policy" and summary["budget"] == 300
    assert "1/1 reached" in printed and data["complete"] and summary["complete"]
    assert data["min_clearance_cm"] >= 1.0 and data["duration_s"] > 0
    assert data["target"] == [170.0, 80.0, 50.0] and data["tip_error_cm"] < 0.1
    assert check.main([str(folder)]) == 0  # time, limits and 1 cm re-checked from the file
    assert view.main([str(folder), "-o", str(tmp_path / "v.html")]) == 0
    assert route.main(argv) == 2  # the motion is there already: not replaced
    assert "a motion is there already" in capsys.readouterr().err


def test_random_targets_and_a_greedy_plan(policy_dir, tmp_path, capsys):
    out = tmp_path / "random"
    argv = ["plan", str(policy_dir), "--random", "2", "--seed", "5", "--budget", "0"]
    argv += ["-o", str(out)]
    assert route.main(argv) == 0
    folders = sorted(out.iterdir())
    assert len(folders) == 2
    for folder in folders:
        data = json.loads((folder / "trajectory.json").read_text())
        assert isinstance(data["complete"], bool) and len(data["target"]) == 3
        if not data["complete"]:
            assert "no route within 0 env steps" in data["reason"]
    seeds = sorted(json.loads((f / "summary.json").read_text())["seed"] for f in folders)
    assert seeds == [5, 6]
    assert "/2 reached" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["plan", "-o", "X", *HATCH], "give a policy DIR or --pretrained NAME"),
        (["plan", "P", "--pretrained", "route-bay2", "-o", "X", *HATCH], "give a policy DIR"),
        (["plan", "--pretrained", "nope", "-o", "X", *HATCH], "no shipped route policy named"),
        (["plan", "P", "-o", "X"], "give --target X Y Z (repeatable) or --random N"),
        (["plan", "/nonexistent/p", "-o", "X", *HATCH], "/nonexistent/p/config.json"),
        (["plan", "P", "--budget", "-1", "-o", "X", *HATCH], "--budget"),
        (["train", "-o", "X", "--routes", "0"], "--routes"),
    ],
)
def test_refused_command_lines_are_one_line(argv, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "P").mkdir()
    (tmp_path / "P" / "config.json").write_text('{"env_kwargs": {"bay": 2}}')
    assert route.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    assert not (tmp_path / "X").exists()


@pytest.mark.parametrize(
    "config",
    [b"[]", b'{"env_kwargs": []}', b'{"env_kwargs": {"bay": "2"}}', b'{"env_kwargs": {"bay": 1.0}}',
     b"\xff\xfe{", b"{" * 100_000, b'{"env_kwargs": {"bay": 3}}',
     b'{"env_id": "AFTIR-Tank-v0", "env_kwargs": {"bay": 2}}',
     b'{"env_id": "os:AFTIR-ArmRoute-v1", "env_kwargs": {"bay": 2}}'],
)  # fmt: skip
def test_a_policy_folder_with_a_broken_config_is_one_line(config, tmp_path, capsys):
    (tmp_path / "P").mkdir()
    (tmp_path / "P" / "config.json").write_bytes(config)
    argv = ["plan", str(tmp_path / "P"), *HATCH, "-o", str(tmp_path / "X")]
    assert route.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "config" in err and "Traceback" not in err
    assert not (tmp_path / "X").exists()


def test_a_policy_of_the_first_version_plans_in_that_version(policy_dir, tmp_path, capsys):
    """A v0 policy's config names AFTIR-ArmRoute-v0: its leads and moves, not v1's."""
    import argparse

    old = tmp_path / "v0"
    old.mkdir()
    config = json.loads((policy_dir / "config.json").read_text())
    (old / "config.json").write_text(json.dumps({**config, "env_id": "AFTIR-ArmRoute-v0"}))
    (old / route.POLICY_FILE).write_bytes((policy_dir / route.POLICY_FILE).read_bytes())
    env, _, _ = route._plan_env(argparse.Namespace(tank=None, bay=None), old)
    assert env.leads == (-20.0, -10.0, 0.0, 15.0, 30.0) and env.settings.max_change == 0.75
    new, _, _ = route._plan_env(argparse.Namespace(tank=None, bay=None), policy_dir)
    assert new.leads[:2] == (-40.0, -30.0) and new.settings.max_change == 1.0


def test_a_policy_for_another_observation_is_refused(policy_dir, tmp_path, capsys):
    from aftir_rl.rl.route_policy import RoutePolicy, save_route_policy

    other = tmp_path / "other"
    other.mkdir()
    (other / "config.json").write_text((policy_dir / "config.json").read_text())
    save_route_policy(RoutePolicy(7, 25), other / route.POLICY_FILE)
    assert route.main(["plan", str(other), *HATCH, "-o", str(tmp_path / "o")]) == 2
    assert "the policy reads 7 numbers" in capsys.readouterr().err
    assert not np.any([p.name == "trajectory.json" for p in tmp_path.rglob("*")])


@pytest.mark.slow
def test_the_shipped_policy_meets_its_card_on_its_first_test_targets():
    """The card's test (500 targets from seed 4,000,000, all reached with the search): its
    first 40 again, and the four corners the card says it reaches."""
    import torch

    from aftir_rl.core.files import read_json
    from aftir_rl.envs.ftl.route_env import ArmRouteEnv
    from aftir_rl.rl.route_policy import load_route_policy, route_search

    torch.set_num_threads(1)
    folder = route.route_policy_dir(None, "route-bay2")
    card = read_json(folder / "card.json")
    policy, env = load_route_policy(folder / route.POLICY_FILE), ArmRouteEnv(bay=2)
    test = card["test"]
    seeds = range(test["seed"], test["seed"] + 40)
    reached = sum(route_search(env, policy, s, test["search"]["budget"]).success for s in seeds)
    assert reached >= round(40 * test["search"]["success_rate"]) - 1
    for corner, ok in card["corners"].items():
        target = np.array([float(v) for v in corner.strip("()").split(",")])
        assert route_search(env, policy, None, test["search"]["budget"], target).success == ok


@pytest.mark.slow
def test_the_shipped_any_tank_policy_meets_its_card_in_wings_it_never_met(tmp_path):
    """The card's held-out wings (200 targets from seed 4,000,000 across 20 wings): the first
    20, in the first two wings, with the card's search; and it plans only where told."""
    import torch

    from aftir_rl.core.files import read_json
    from aftir_rl.envs.ftl.route_env import ArmRouteEnv
    from aftir_rl.rl.route_policy import load_route_policy, route_search

    torch.set_num_threads(1)
    folder = route.route_policy_dir(None, "route-anytank")
    card = read_json(folder / "card.json")
    policy, test = load_route_policy(folder / route.POLICY_FILE), card["test_wings"]
    first, last = (int(v) for v in test["tanks"].split(":")[2].split("-"))
    envs = [ArmRouteEnv(tank=f"wing:3:{first + w}") for w in (0, 1)]
    per_wing = test["targets"] // (last - first + 1)
    seeds = range(test["seed"], test["seed"] + 2 * per_wing)
    budget = test["search"]["budget"]
    reached = sum(
        route_search(envs[i // per_wing], policy, s, budget).success for i, s in enumerate(seeds)
    )
    assert reached >= round(len(seeds) * test["search"]["success_rate"]) - 1
    out = tmp_path / "X"
    assert (
        route.main(["plan", "--pretrained", "route-anytank", "--random", "1", "-o", str(out)]) == 2
    )
    assert not out.exists()


@pytest.mark.parametrize(
    "targets, message",
    [(["--target", "1e4", "0", "0"], "target"), ([*HATCH, *HATCH], "a target is given twice")],
)
def test_a_target_the_env_refuses_writes_nothing(policy_dir, targets, message, tmp_path, capsys):
    argv = ["plan", str(policy_dir), *targets, "-o", str(tmp_path / "X")]
    assert route.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "Traceback" not in err
    assert not (tmp_path / "X").exists()


def test_a_policy_trained_on_a_stream_plans_in_the_tank_it_is_given(tmp_path, capsys):
    out = tmp_path / "stream"
    argv = ["train", "-o", str(out), "--tank", "wing:2:40+", "--tank-episodes", "1"]
    assert route.main([*argv, "--routes", "2", "--updates", "20", "--no-progress"]) == 0
    config = json.loads((out / "config.json").read_text())
    assert config["env_kwargs"] == {"tank": "wing:2:40+", "tank_episodes": 1}
    capsys.readouterr()
    plan = ["plan", str(out), "--random", "1", "--budget", "20"]
    assert route.main([*plan, "-o", str(tmp_path / "X")]) == 2
    assert "trained in wing:2:40+: give --tank" in capsys.readouterr().err
    assert not (tmp_path / "X").exists()
    assert route.main([*plan, "--tank", "wing:2:41", "-o", str(tmp_path / "m")]) == 0
    (folder,) = (tmp_path / "m").iterdir()
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["tank"] == "wing:2:41" and summary["bay"] is None
    data = json.loads((folder / "trajectory.json").read_text())
    if data["complete"]:  # re-checked in the wing the summary names
        assert check.main([str(folder)]) == 0


@pytest.mark.parametrize(
    "argv, message",
    [(["--tank-episodes", "3"], "--tank-episodes is a stream's"),
     (["--tank", "wing:2:1-3", "--tank-episodes", "3"], "--tank-episodes is a stream's"),
     (["--tank", "/nonexistent/t.yaml"], "/nonexistent/t.yaml"),
     (["--bay", "5"], "bay")],
)  # fmt: skip
def test_a_tank_or_bay_training_cannot_use_is_one_line(argv, message, tmp_path, capsys):
    assert route.main(["train", "-o", str(tmp_path / "X"), "--routes", "1", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "Traceback" not in err
    assert not (tmp_path / "X").exists()


def test_evaluate_prints_one_row_per_tank_and_pool_as_the_search_scores_them(tmp_path, capsys):
    """Each row is route_success of the policy on its targets (a pool's spread over its wings);
    the JSON holds the same; an existing --json is refused before any search."""
    from aftir_rl.envs.ftl.route_env import route_env
    from aftir_rl.rl.route_policy import load_route_policy, route_success

    out = tmp_path / "eval.json"
    argv = ["evaluate", "--pretrained", "route-bay2", "--tank", "b737_center", "--tank"]
    argv += ["wing:2:5-6", "--random", "3", "--seed", "11", "--budget", "5", "20"]
    assert route.main([*argv, "--no-progress", "--json", str(out)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].startswith("| tanks | targets | greedy (%) | best first 5 (%) | best first 20")
    names = [row.split(" | ")[0] for row in lines[2:]]
    assert names == ["| b737_center, the whole tank", "| wing:2:5-6"]
    rows = json.loads(out.read_text())["rows"]
    folder = route.route_policy_dir(None, "route-bay2")
    policy = load_route_policy(folder / route.POLICY_FILE)
    env_id = json.loads((folder / "config.json").read_text())["env_id"]  # its version's env
    envs = [[route_env(env_id, tank="b737_center")]]
    envs.append([route_env(env_id, tank=f"wing:2:{s}") for s in (5, 6)])
    for row, env in zip(rows, envs, strict=True):
        expected = route_success(env, policy, [11, 12, 13], [5, 20])
        assert {k: v for k, v in row.items() if k != "tanks"} == expected
    before = out.read_bytes()
    assert route.main([*argv, "--json", str(out)]) == 2
    assert out.read_bytes() == before and "exists" in capsys.readouterr().err
