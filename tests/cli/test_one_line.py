"""Every refused command line is one line, ``error: ... (see --help)``, and exit status 2.

Counts and seeds are bounded with the bound in the message; ``--target`` takes finite numbers
(``-1e3`` and ``-inf`` are values, not options); a search space draws what its hyperparameter
takes.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

from aftir_rl.cli.args import OneLineParser, add_target_option, bounded_int
from aftir_rl.core.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ") and lines[0].endswith("(see --help)"), err
    return lines[0]


@pytest.mark.parametrize(
    "module, argv, message",
    [
        ("view", ["run", "--max-frames", "0"], "--max-frames must be from 2 to 1,000, got 0"),
        (
            "view",
            ["run", "--max-frames", "1000000"],
            "--max-frames must be from 2 to 1,000, got 1000000",
        ),
        ("bench", ["--n-random", "-1"], "--n-random must be from 1 to 1,000, got -1"),
        ("bench", ["--n-random", "1000000000"], "--n-random must be from 1 to 1,000"),
        ("bench", ["--seed", "2e40"], "--seed must be from 0 to 4,294,967,295"),
        ("bench", ["--workers", "0"], "--workers must be from 1 to 1,024, got 0"),
        ("plan", ["--target", "0", "-inf", "0"], "--target must be finite numbers"),
        ("plan", ["--target", "0", "nan", "0"], "--target must be finite numbers"),
        ("plan", ["--target", "1e300", "0", "0"], "at most 10,000 cm in magnitude"),
        ("plan", [], "the following arguments are required: --target"),
        ("train", ["q_table", "--episodes", str(10**12)], "--episodes must be from 1 to 1,000,000"),
        ("train", ["q_table", "--seed", "-1"], "--seed must be from 0 to 4,294,967,295, got -1"),
        ("train", ["q_table", "--target", "1", "inf", "2"], "--target must be finite"),
        ("train", ["ppo", "--total-timesteps", "1e12"], "--total-timesteps must be from 0 to"),
        ("train", ["ppo", "--n-envs", "5000"], "--n-envs must be from 1 to 4,096"),
        ("train", ["nope"], "invalid choice: 'nope'"),
        ("train", [], "the following arguments are required: ALGO"),
        ("evaluate", ["run", "--random", str(10**9)], "--random must be from 1 to 10,000"),
        ("evaluate", ["run", "--seed", str(2**32)], "--seed must be from 0 to 4,294,967,295"),
        ("tune", ["ppo", "--trials", "0"], "--trials must be from 1 to 10,000, got 0"),
        ("tune", ["ppo", "--evaluations", "101"], "--evaluations must be from 1 to 100"),
        ("tune", ["ppo", "--workers", "100000"], "--workers must be from 1 to 1,024"),
        ("tune", ["ppo", "--total-timesteps", "0"], "--total-timesteps must be from 1"),
        ("tank", ["--bogus"], "unrecognized arguments: --bogus"),
        ("evaluate", ["run", *["--target", "1", "2", "3"] * 1001], "at most 1,000 times"),
    ],
)
def test_refused_command_lines_are_one_line(module, argv, message, capsys):
    main = importlib.import_module(f"aftir_rl.cli.{module}").main
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert message in _one_line(captured.err) and captured.out == ""


@pytest.mark.parametrize(
    "argv, message",
    [
        (["-m", "aftir_rl.view", "run", "--max-frames", "0"], "--max-frames must be from 2"),
        (["-m", "aftir_rl.cli", "plan", "--target", "0", "-inf", "0"], "--target must be finite"),
    ],
)
def test_one_line_in_a_process(argv, message):
    run = subprocess.run(
        [sys.executable, *argv], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert run.returncode == 2 and message in _one_line(run.stderr)


def test_rank_checkpoints_is_one_line(capsys):
    spec = importlib.util.spec_from_file_location("rank", ROOT / "benchmarks/rank_checkpoints.py")
    assert spec is not None and spec.loader is not None
    rank = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rank)
    assert rank.main(["run", "--fresh", "0"]) == 2
    assert "--fresh must be from 1 to 4,096" in _one_line(capsys.readouterr().err)


def test_bounded_int():
    parse = bounded_int(1, 1000)
    assert parse("7") == 7 and parse("1e3") == 1000 and parse("1_000") == 1000
    for text, message in [
        ("0", "must be from 1 to 1,000, got 0"),
        ("1001", "must be from 1 to 1,000, got 1001"),
        ("2.5", "must be an integer from 1 to 1,000, got 2.5"),
        ("nan", "must be an integer"),
        ("1" * 5000, "must be an integer"),  # past int()'s digit limit: refused, one line
    ]:
        with pytest.raises(argparse.ArgumentTypeError, match=message) as info:
            parse(text)
        assert len(str(info.value)) < 100


def test_negative_numbers_are_values():
    parser = OneLineParser(prog="p")
    add_target_option(parser, "a target")
    assert parser.parse_args(["--target", "-1e3", "-.5", "-2"]).target == [[-1000.0, -0.5, -2.0]]
    assert parser.parse_args(["--target", *"123", "--target", *"456"]).target == [
        [1.0, 2.0, 3.0],
        [4.0, 5.0, 6.0],
    ]
    assert parser.parse_args([]).target is None
    with pytest.raises(ConfigError, match="^--target must be finite numbers .* got -inf"):
        parser.parse_args(["--target", "0", "-inf", "0"])


# ------------------------------------------------------------------ search spaces


@pytest.fixture(scope="module")
def ppo_base():
    from aftir_rl.rl.sb3 import entry_config

    return entry_config("ppo", "AFTIR-ArmReach-v0")


@pytest.mark.parametrize(
    "space, message",
    [
        ("n_steps: {uniform: [64, 2048]}", "n_steps: n_steps takes integers, and uniform"),
        ("batch_size: {loguniform: [64, 512]}", "batch_size takes integers, and loguniform"),
        ("n_epochs: {choice: [5, 7.5]}", "n_epochs.choice[1]: n_epochs takes integers, got 7.5"),
        ("n_epochs: {choice: [true]}", "n_epochs takes integers, got True"),
    ],
)
def test_a_search_space_must_draw_the_type_of_its_hyperparameter(
    tmp_path, ppo_base, space, message
):
    from aftir_rl.experiments.search_space import load_search_space

    path = tmp_path / "space.yaml"
    path.write_text(f"hyperparameters:\n  {space}\n")
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_search_space(path, "ppo", ppo_base)


def test_integer_choices_are_given_as_integers(tmp_path, ppo_base):
    from aftir_rl.experiments.search_space import load_search_space

    path = tmp_path / "space.yaml"
    path.write_text(
        "hyperparameters:\n  n_steps: {choice: [64.0, '128']}\n  n_epochs: {randint: [2, 9]}\n"
        "  gamma: {uniform: [0.9, 0.99]}\n"
    )
    steps, epochs, gamma = load_search_space(path, "ppo", ppo_base)
    assert steps.values == (64, 128) and all(type(v) is int for v in steps.values)
    assert (epochs.kind, epochs.values) == ("randint", (2, 9))
    assert (gamma.kind, gamma.values) == ("uniform", (0.9, 0.99))
