"""``aftir rollout`` and ``aftir record``: a trained policy's motion, drawn like the planner's."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from aftir_rl.cli import record, rollout, train
from aftir_rl.core.robot import Posture
from aftir_rl.viz.page import read_run, write_view

FTL_YAML = (
    "env_id: AFTIR-ArmFTL-v0\nn_envs: 8\neval_freq: 100000\neval_targets: 1\n"
    "checkpoint_freq: 100000\npolicy: MultiInputPolicy\nenv_kwargs:\n  bay: 2\n  guide: true\n"
    "hyperparameters:\n  n_steps: 16\n  batch_size: 64\n  n_epochs: 1\n"
    "  policy_kwargs:\n    net_arch: [16]\n"
)


@pytest.fixture(scope="module")
def ftl_run(tmp_path_factory):
    top = tmp_path_factory.mktemp("ftl")
    (top / "ftl.yaml").write_text(FTL_YAML)
    argv = ["ppo", "--config", str(top / "ftl.yaml"), "--total-timesteps", "128"]
    assert train.main([*argv, "--logdir", str(top / "runs"), "--no-progress"]) == 0
    return next((top / "runs").iterdir())


def test_rollout_writes_the_planner_contract_and_view_draws_it(ftl_run, tmp_path, capsys):
    out = tmp_path / "out"
    targets = ["--target", "230", "140", "90", "--target", "150", "120", "60"]
    assert rollout.main([str(ftl_run), *targets, "-o", str(out)]) == 0
    assert "/2 reached; aftir view" in capsys.readouterr().out
    folder = out / "target_230.0_140.0_90.0"
    data = json.loads((folder / "trajectory.json").read_text())
    assert data["steps"] == len(data["motion"]) - 1 > 0
    assert data["target"] == [230.0, 140.0, 90.0]
    last = data["motion"][-1]  # the tip error is the last posture's, by forward kinematics
    tip = Posture(last["dis"], last["theta"], last["phi"]).tip(data["section_length"])
    assert np.linalg.norm(tip - np.array(data["target"])) == pytest.approx(
        data["tip_error_cm"], abs=1e-6
    )
    run = read_run(folder)
    assert run.n_motion == len(data["motion"]) and run.tank == "b737_center"
    write_view([folder, out / "target_150.0_120.0_60.0"], tmp_path / "v.html")
    assert (tmp_path / "v.html").stat().st_size > 100_000


@pytest.mark.slow  # renders 300 frames
def test_record_writes_a_gif(ftl_run, tmp_path):
    gif = tmp_path / "arm.gif"
    argv = [str(ftl_run), "--random", "1", "-o", str(gif), "--every", "10", "--no-progress"]
    assert record.main(argv) == 0
    with Image.open(gif) as image:
        assert image.n_frames > 10 and image.size == (512, 384)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["-o", "x"], "give --target"),
        (["--target", "1", "2", "3", "--random", "2", "-o", "x"], "give --target"),
        (["--random", "0", "-o", "x"], "--random must be from 1"),
    ],
)
def test_bad_requests_are_one_line(ftl_run, tmp_path, argv, message, capsys):
    assert rollout.main([str(ftl_run), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
