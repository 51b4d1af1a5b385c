"""RLlib's PPO through ``aftir train ppo --rllib``: on a two-node Ray cluster, resumed, evaluated.

The cluster is real: a head node and a worker node, each a raylet of its own with one CPU
(Ray's ``cluster_utils.Cluster``), and two env runners, so one runs on each node. The
commands run in subprocesses that join it by address, as a user's would.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from aftir_rl.core.errors import CheckpointError, ConfigError
from aftir_rl.rl.sb3.config import SB3Config

ROOT = Path(__file__).resolve().parents[2]
#: A few short PPO updates of the batched FTL env: 8 rows × 64 steps per update.
SMALL = [
    "--env", "AFTIR-ArmFTL-v0", "--n-envs", "8", "--eval-episodes", "2", "--no-progress",
    "--hyperparams", "n_steps:64", "batch_size:256", "n_epochs:1",
]  # fmt: skip


def _aftir(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "RAY_USAGE_STATS_ENABLED": "0"}
    return subprocess.run(
        [sys.executable, "-m", "aftir_rl.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
        env=env,
    )


@pytest.fixture(scope="module")
def cluster():
    """A Ray cluster of two nodes (head and worker, one CPU each); its address."""
    from ray.cluster_utils import Cluster

    nodes = Cluster(
        initialize_head=True,
        head_node_args={"num_cpus": 1, "include_dashboard": False},
    )
    nodes.add_node(num_cpus=1)
    nodes.wait_for_nodes()
    try:
        yield nodes.address
    finally:
        nodes.shutdown()


def _runs(logdir: Path) -> list[Path]:
    return sorted(logdir.glob("rllib-ppo__AFTIR-ArmFTL-v0__*"))


def _tags(run_dir: Path) -> set[str]:
    events = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})
    events.Reload()
    return set(events.Tags()["scalars"])


@pytest.mark.slow
def test_ppo_on_a_two_node_cluster_resumes_and_is_evaluated(cluster, tmp_path):
    import ray

    ray.init(address=cluster, logging_level="error")
    try:
        nodes = [n for n in ray.nodes() if n["Alive"]]
        assert len(nodes) == 2 and all(n["Resources"]["CPU"] == 1 for n in nodes)
    finally:
        ray.shutdown()
    logdir = tmp_path / "runs"
    train = ["train", "ppo", "--rllib", "--ray", cluster, "--env-runners", "2", *SMALL]
    out = _aftir(*train, "--total-timesteps", "1024", "--save-freq", "512", "--logdir", str(logdir))
    assert out.returncode == 0, out.stderr[-3000:]
    assert "Traceback" not in out.stderr
    (run,) = _runs(logdir)
    config = json.loads((run / "config.json").read_text())
    assert config["algo"] == "ppo" and config["n_envs"] == 8
    meta = json.loads((run / "rllib.json").read_text())
    assert meta["env_runners"] == 2 and meta["nodes"] == 2 and meta["cpus"] == 2
    summary = json.loads((run / "summary.json").read_text())
    assert summary["timesteps"] >= 1024 and summary["library"] == "rllib"
    saved = sorted(int(p.stem.split("_")[1]) for p in (run / "checkpoints").glob("learner_*.pt"))
    assert saved[0] >= 512 and saved[-1] == summary["timesteps"]
    tags = _tags(run)
    for tag in ("eval/success_rate", "eval/min_clearance_cm", "train/loss", "time/fps"):
        assert tag in tags, sorted(tags)
    assert (run / "best" / "rllib_module.pt").exists()

    # the SB3 commands read it: evaluate (here two held-out targets), rollout, view
    out = _aftir("evaluate", str(run), "--random", "2", "--seed", "7", "--logdir", str(tmp_path))
    assert out.returncode == 0, out.stderr[-2000:]
    assert "ppo RLlib (AFTIR-ArmFTL-v0)" in out.stdout
    out = _aftir("rollout", str(run / "best"), "--random", "1", "-o", str(tmp_path / "roll"))
    assert out.returncode == 0, out.stderr[-2000:]
    (motion,) = (tmp_path / "roll").glob("*/trajectory.json")
    assert json.loads(motion.read_text())["motion"]
    out = _aftir("view", str(run), str(motion.parent), "-o", str(tmp_path / "view.html"))
    assert out.returncode == 0, out.stderr[-2000:]
    assert (tmp_path / "view.html").stat().st_size > 100_000

    # resumed with no steps to train: the learner's weights are the checkpoint's, exactly
    again = tmp_path / "again"
    resume = ["--resume", str(run), "--logdir", str(again)]
    out = _aftir(*train, "--total-timesteps", "0", *resume)
    assert out.returncode == 0, out.stderr[-3000:]
    (resumed,) = _runs(again)
    before = torch.load(run / "rllib_module.pt", weights_only=True)
    after = torch.load(resumed / "rllib_module.pt", weights_only=True)
    assert before.keys() == after.keys()
    assert all(torch.equal(before[k], after[k]) for k in before)
    # its steps go on from the checkpoint's (training on is the first run's loop)
    assert json.loads((resumed / "summary.json").read_text())["timesteps"] == saved[-1]


def test_the_sb3_config_becomes_rllibs_ppo_settings():
    from aftir_rl.rl.rllib.config import SB3_PPO_DEFAULTS, check_rllib_config, ppo_config

    config = SB3Config(
        env_id="AFTIR-ArmFTL-v0",
        n_envs=8,
        hyperparameters={
            "learning_rate": 1e-4,
            "n_steps": 32,
            "batch_size": 64,
            "gamma": 0.98,
            "policy_kwargs": {"net_arch": [32, 16]},
        },
        env_kwargs={"bay": 1},
    )
    check_rllib_config(config, 2)
    ppo = ppo_config(config, "AFTIR-ArmFTL-v0", seed=3, env_runners=2)
    assert ppo.lr == 1e-4 and ppo.gamma == 0.98 and ppo.minibatch_size == 64
    assert ppo.train_batch_size_per_learner == 32 * 8  # SB3's rollout: n_steps × n_envs
    assert ppo.num_envs_per_env_runner == 4 and ppo.rollout_fragment_length == 32
    assert ppo.num_epochs == SB3_PPO_DEFAULTS["n_epochs"]  # left out: SB3's default
    assert ppo.clip_param == SB3_PPO_DEFAULTS["clip_range"] and not ppo.use_kl_loss
    assert ppo.model_config["fcnet_hiddens"] == [32, 16]
    assert ppo.gym_env_vectorize_mode == "vector_entry_point"  # the batched env, not copies
    assert ppo.env_config == {"bay": 1} and ppo.seed == 3
    reach = ppo_config(SB3Config(env_id="AFTIR-ArmReach-v0", n_envs=2), "AFTIR-ArmReach-v0", 0, 1)
    assert reach.gym_env_vectorize_mode == "sync"


def test_the_sb3_sac_config_becomes_rllibs_sac_settings():
    from aftir_rl.rl.rllib.config import SB3_SAC_DEFAULTS, check_rllib_config, rllib_config

    hyper = {"batch_size": 128, "train_freq": 4, "gradient_steps": 2, "ent_coef": "auto_0.1"}
    config = SB3Config(env_id="AFTIR-ArmReach-v0", n_envs=2, hyperparameters=hyper)
    check_rllib_config(config, 1, algo="sac")
    sac = rllib_config("sac", config, "AFTIR-ArmReach-v0", seed=0, env_runners=1)
    assert sac.actor_lr == sac.critic_lr == sac.alpha_lr == SB3_SAC_DEFAULTS["learning_rate"]
    assert sac.train_batch_size_per_learner == 128 and sac.rollout_fragment_length == 4
    assert sac.training_intensity == 2 * 128 / (4 * 2)  # trained / sampled steps, as SB3's
    assert sac.initial_alpha == 0.1 and sac.target_entropy == "auto" and sac.twin_q
    assert sac.replay_buffer_config["type"] == "EpisodeReplayBuffer"  # uniform, as SB3's
    assert sac.replay_buffer_config["capacity"] == SB3_SAC_DEFAULTS["buffer_size"]
    assert sac.model_config["fcnet_hiddens"] == [256, 256]


@pytest.mark.parametrize(
    ("config", "algo", "message"),
    [
        (SB3Config(hyperparameters={"ent_coef": 0.1}), "sac", "learns its temperature"),
        (SB3Config(hyperparameters={"train_freq": [1, "episode"]}), "sac", "must be a number"),
        (SB3Config(hyperparameters={"n_steps": 64}), "sac", "no counterpart in RLlib's SAC"),
        (SB3Config(), "td3", "RLlib trains ppo and sac here"),
    ],
)
def test_what_rllibs_sac_cannot_train_as_sb3_would_is_refused(config, algo, message):
    from aftir_rl.rl.rllib.config import check_rllib_config

    with pytest.raises(ConfigError, match=message):
        check_rllib_config(config, 1, algo=algo)


@pytest.mark.slow
def test_sac_trains_on_a_local_ray_and_is_evaluated(tmp_path):
    logdir = tmp_path / "runs"
    out = _aftir(
        "train", "sac", "--rllib", "--env-runners", "0", "--env", "AFTIR-ArmReach-v0",
        "--total-timesteps", "200", "--hyperparams", "learning_starts:100",
        "--eval-episodes", "2", "--no-progress", "--logdir", str(logdir),
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    (run,) = logdir.glob("rllib-sac__AFTIR-ArmReach-v0__*")
    assert json.loads((run / "config.json").read_text())["algo"] == "sac"
    assert "train/critic_loss" in _tags(run) and "eval/success_rate" in _tags(run)
    out = _aftir("evaluate", str(run), "--random", "2", "--logdir", str(tmp_path))
    assert out.returncode == 0 and "sac RLlib (AFTIR-ArmReach-v0)" in out.stdout, out.stderr


class _Random:
    """Uniformly random actions (seeded), with SB3's ``predict``."""

    def __init__(self, space) -> None:
        self.space = space
        self.space.seed(0)

    def predict(self, observation, *, deterministic: bool = True):
        return self.space.sample(), None


@pytest.mark.slow
def test_ppo_by_rllib_learns_to_reach_targets_random_actions_miss(cluster, tmp_path):
    """ArmReach's shipped entry for 60k steps (about a minute): >= 15 points above random."""
    import gymnasium as gym

    from aftir_rl.experiments.runs import evaluate_run
    from aftir_rl.rl.sb3 import evaluate_policy_on_targets, evaluation_targets

    env_id = "AFTIR-ArmReach-v0"
    out = _aftir(
        "train", "ppo", "--rllib", "--ray", cluster, "--env-runners", "0", "--env", env_id,
        "--total-timesteps", "60000", "--eval-episodes", "10", "--no-progress",
        "--logdir", str(tmp_path),
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    (run,) = tmp_path.glob(f"rllib-ppo__{env_id}__*")
    targets = evaluation_targets(env_id, 50, seed=5_000_000)  # seeds no training drew
    learnt = evaluate_run(run, targets=targets)
    random, _ = evaluate_policy_on_targets(_Random(gym.make(env_id).action_space), env_id, targets)
    assert learnt["success_rate"] >= random["success_rate"] + 0.15, (learnt, random)


@pytest.mark.parametrize(
    ("config", "runners", "message"),
    [
        (SB3Config(her=True), 1, "no HER here"),
        (SB3Config(hyperparameters={"use_sde": True}), 1, "no counterpart in RLlib"),
        (SB3Config(hyperparameters={"learning_rate": "lin_3e-4"}), 1, "must be a number"),
        (SB3Config(hyperparameters={"policy_kwargs": {"ortho_init": False}}), 1, "net_arch only"),
        (SB3Config(n_envs=3), 2, "cannot be shared by 2 env runners"),
    ],
)
def test_what_rllib_cannot_train_as_sb3_would_is_refused(config, runners, message):
    from aftir_rl.rl.rllib.config import check_rllib_config

    with pytest.raises(ConfigError, match=message):
        check_rllib_config(config, runners)


class _Boom:
    def __reduce__(self):
        return (os.system, ("touch /tmp/aftir-rllib-pwned",))


def test_weights_are_read_as_tensors_only(tmp_path):
    from aftir_rl.rl.tensors import as_tensors, load_tensors, save_tensors

    state = {"learner": {"w": np.arange(6.0).reshape(2, 3), "step": np.float32(2.0), 7: [1, 2]}}
    path = save_tensors(state, tmp_path / "ok.pt")
    back = load_tensors(path, "weights")
    assert torch.equal(back["learner"]["w"], as_tensors(state)["learner"]["w"])
    assert back["learner"][7] == [1, 2] and back["learner"]["step"] == 2.0
    hostile = tmp_path / "rllib_module.pt"
    buffer = io.BytesIO()
    torch.save({"w": _Boom()}, buffer, pickle_protocol=2)
    hostile.write_bytes(buffer.getvalue())
    Path("/tmp/aftir-rllib-pwned").unlink(missing_ok=True)
    with pytest.raises(CheckpointError, match="not an RLlib run's weights"):
        load_tensors(hostile, "an RLlib run's weights")
    assert not Path("/tmp/aftir-rllib-pwned").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--ray", "local"], "--ray is an RLlib option: add --rllib"),
        (["--env-runners", "2"], "--env-runners is an RLlib option: add --rllib"),
        (["--rllib", "--env", "AFTIR-ArmFTL-v0", "--n-envs", "3", "--env-runners", "2"],
         "cannot be shared by 2 env runners"),
    ],
)  # fmt: skip
def test_rllib_options_are_checked_in_one_line(args, message, tmp_path):
    out = _aftir("train", "ppo", *args, "--logdir", str(tmp_path), timeout=120)
    assert out.returncode == 2, out.stderr[-2000:]
    assert message in out.stderr and "Traceback" not in out.stderr
    assert out.stderr.strip().count("\n") == 0
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize(
    "state",
    [[], {"learner": []}, {"learner": {"rl_module": {"default_policy": 3}}}, torch.zeros(3)],
)
def test_a_file_that_is_no_learner_state_is_refused(state, tmp_path):
    from aftir_rl.rl.rllib.train import RLLIB_FILE, _resumed
    from aftir_rl.rl.tensors import save_tensors

    (tmp_path / RLLIB_FILE).write_text("{}")
    save_tensors(state, tmp_path / "checkpoints" / "learner_5.pt")
    with pytest.raises(CheckpointError, match="not an RLlib learner state"):
        _resumed(tmp_path)


def test_weights_of_another_network_are_refused():
    import gymnasium as gym

    from aftir_rl.rl.rllib.config import build_module
    from aftir_rl.rl.rllib.policy import RLlibPolicy

    env = gym.make("aftir_rl:AFTIR-ArmReach-v0")
    small = SB3Config(hyperparameters={"policy_kwargs": {"net_arch": [32, 32]}})
    policy = RLlibPolicy(
        build_module(SB3Config(), env.observation_space, env.action_space),
        env.observation_space,
        env.action_space,
    )
    other = build_module(small, env.observation_space, env.action_space).state_dict()
    with pytest.raises(CheckpointError, match="wrong shape"):
        policy.load_weights(other, "other.pt")
    weights = policy.module.state_dict()
    with pytest.raises(CheckpointError, match="tensors differ"):
        policy.load_weights({k: v for k, v in list(weights.items())[1:]}, "fewer.pt")
    weights = {k: v.clone() for k, v in weights.items()}
    next(iter(weights.values())).view(-1)[0] = float("nan")
    with pytest.raises(CheckpointError, match="not finite"):
        policy.load_weights(weights, "nan.pt")
    action, _ = policy.predict(env.reset(seed=0)[0])
    assert env.action_space.contains(action.astype(env.action_space.dtype))


def _rllib_run(folder: Path) -> Path:
    """An RLlib run directory of ``AFTIR-ArmReach-v0`` as the trainer writes it (random weights)."""
    import dataclasses

    import gymnasium as gym

    from aftir_rl.rl.rllib.config import build_module
    from aftir_rl.rl.rllib.policy import MODULE_FILE
    from aftir_rl.rl.tensors import save_tensors

    config = SB3Config(env_id="AFTIR-ArmReach-v0", eval_targets=2)
    env = gym.make("aftir_rl:AFTIR-ArmReach-v0")
    module = build_module(config, env.observation_space, env.action_space)
    folder.mkdir(parents=True)
    params = {**dataclasses.asdict(config), "algo": "ppo", "seed": 0, "resume": None}
    (folder / "config.json").write_text(json.dumps(params))
    (folder / "rllib.json").write_text(json.dumps({"library": "rllib", "env_runners": 1}))
    save_tensors(module.state_dict(), folder / MODULE_FILE)
    return folder


def _zip_bomb(path: Path) -> None:
    """A tensor file whose one record inflates to 300 MB, past the limit (stored deflated)."""
    import zipfile

    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        with z.open("archive/data/0", "w", force_zip64=True) as sink:
            block = bytes(1 << 20)
            for _ in range(300):
                sink.write(block)


@pytest.mark.parametrize(
    "poison",
    ["pickle", "truncated", "garbage", "bomb", "other-net", "rllib-json", "not-a-dict"],
)
def test_a_hostile_rllib_run_runs_nothing_and_says_one_line(poison, tmp_path, capsys):
    from aftir_rl.cli import evaluate

    run = _rllib_run(tmp_path / "run")
    weights = run / "rllib_module.pt"
    marker = Path("/tmp/aftir-rllib-pwned")
    marker.unlink(missing_ok=True)
    if poison == "pickle":
        buffer = io.BytesIO()
        torch.save({"w": _Boom()}, buffer, pickle_protocol=2)
        weights.write_bytes(buffer.getvalue())
    elif poison == "truncated":
        weights.write_bytes(weights.read_bytes()[:500])
    elif poison == "garbage":
        weights.write_bytes(os.urandom(4096))
    elif poison == "bomb":
        _zip_bomb(weights)
    elif poison == "other-net":
        torch.save({"pi.net.mlp.0.weight": torch.zeros(3, 3)}, weights)
    elif poison == "rllib-json":
        (run / "rllib.json").write_bytes(b"\xff{")
    else:
        torch.save([torch.zeros(2)], weights)
    out = tmp_path / "ev"
    assert evaluate.main([str(run), "--logdir", str(out), "--random", "1"]) == 2
    err = capsys.readouterr().err
    assert err.strip().count("\n") == 0 and "Traceback" not in err, err
    assert str(run) in err
    assert not marker.exists()


def test_an_rllib_run_is_evaluated_and_rolled_out_without_ray(tmp_path, capsys):
    from aftir_rl.cli import evaluate, rollout

    run = _rllib_run(tmp_path / "run")
    assert evaluate.main([str(run), "--logdir", str(tmp_path / "ev"), "--random", "2"]) == 0
    assert "ppo RLlib (AFTIR-ArmReach-v0)" in capsys.readouterr().out
    out = tmp_path / "roll"
    assert rollout.main([str(run), "--target", "20", "10", "60", "-o", str(out)]) == 0
    (motion,) = out.glob("*/trajectory.json")
    assert json.loads(motion.read_text())["steps"] >= 1


class _Diverging:
    """What RLlib's ``Algorithm.train`` returns once a loss overflows (its weights may not)."""

    def train(self) -> dict:
        losses = {"total_loss": float("nan"), "policy_loss": 0.1}
        return {
            "env_runners": {"num_env_steps_sampled_lifetime": 64},
            "learners": {"default_policy": losses},
        }


def test_a_loss_that_is_not_finite_keeps_the_run_and_says_so(tmp_path):
    from aftir_rl.rl.rllib import train as rllib_train

    env_id = "aftir_rl:AFTIR-ArmReach-v0"
    config = SB3Config(total_timesteps=128, eval_freq=64, checkpoint_freq=64)
    policy = rllib_train._policy(config, env_id, "ppo")
    trainer = rllib_train._Trainer(_Diverging(), "ppo", config, env_id, policy, [], 0, None)
    with pytest.raises(rllib_train.TrainingFailed, match="diverged at step 64"):
        trainer.run(tmp_path / "run", False, {"env_runners": 1})
    (kept,) = tmp_path.glob(".run.partial")
    assert json.loads((kept / "diverged.json").read_text())["step"] == 64
    assert (kept / "config.json").exists() and (kept / "progress.csv").exists()
    assert not (tmp_path / "run").exists()
