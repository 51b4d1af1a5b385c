"""Stage files: a curriculum as one config, each stage resumed from the one before."""

from __future__ import annotations

import pytest

from aftir_rl.core.errors import ConfigError
from aftir_rl.rl.sb3.hyperparams import MAX_STAGES, is_curriculum, load_curriculum
from aftir_rl.rl.sb3.train import train_curriculum


def test_the_shipped_recipe_is_one_stage_file():
    assert is_curriculum("ppo_ftl_curriculum") and not is_curriculum("ppo_ftl")
    bay1, bay2 = load_curriculum("ppo_ftl_curriculum", "ppo")
    assert bay1.env_kwargs["bay"] == 1 and bay2.env_kwargs["bay"] == 2
    assert bay2.total_timesteps == 58_032_128 and bay2.env_kwargs["failure_bias"] == 0.5


def _write(tmp_path, text):
    path = tmp_path / "stages.yaml"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize(
    "text, match",
    [
        ("stages: ppo\n", "a list of stages"),
        ("stages: []\n", "a list of stages"),
        ("stages: [{config: ppo_ftl}]\nextra: 1\n", "one key"),
        ("stages: [{conf: ppo_ftl}]\n", r"stages\[0\]: expected a mapping with a config"),
        ("stages: [{config: ppo_ftl, seed: 3}]\n", "unknown key 'seed'"),
        ("stages: [{config: ppo_ftl_curriculum}]\n", "stage file itself"),
        ("stages: [{env_id: AFTIR-ArmReach-v0}, {config: ppo_ftl}]\n", "same env"),
        ("stages: [{config: ppo_ftl, total_timesteps: -1}]\n", "total_timesteps"),
        ("stages: [{config: ppo_ftl, env_kwargs: {bay: x}}]\n", "bay"),
        ("stages: [{config: /etc/passwd}]\n", "passwd"),
        ("stages: [" + ", ".join(["{config: ppo_ftl}"] * (MAX_STAGES + 1)) + "]\n", "at most"),
    ],
)
def test_bad_stage_files_are_one_line(tmp_path, text, match):
    with pytest.raises(ConfigError, match=match) as info:
        load_curriculum(_write(tmp_path, text), "ppo")
    assert "\n" not in str(info.value)


def test_each_stage_resumes_from_the_one_before(tmp_path):
    calls = []

    def fake_train(algo, config, seed, logdir, resume, **kwargs):
        calls.append((config.total_timesteps, seed, logdir.name, resume, kwargs))
        return {"run_dir": f"{logdir}/run", "timesteps": config.total_timesteps}

    configs = load_curriculum("ppo_ftl_curriculum", "ppo")
    out = train_curriculum(fake_train, "ppo", configs, 7, tmp_path, "start.zip", progress_bar=False)
    assert [c[2] for c in calls] == ["stage0", "stage1"]
    assert calls[0][3] == "start.zip" and calls[1][3] == f"{tmp_path}/stage0/run"
    assert all(c[1] == 7 and c[4] == {"progress_bar": False} for c in calls)
    assert [s["timesteps"] for s in out] == [3_000_000, 58_032_128]
