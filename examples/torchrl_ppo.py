"""TorchRL's PPO on the batched follow-the-leader env: its collector, GAE and clipped loss.

TorchRL's PPO recipe (``Collector``, ``GAE``, ``ClipPPOLoss``, a ``TanhNormal``
``ProbabilisticActor`` and a ``ValueOperator``, minibatches drawn without replacement) over one
``AFTIR-ArmFTL-v0`` vector env: ``GymWrapper(gym.make_vec("aftir_rl:AFTIR-ArmFTL-v0", n,
autoreset_mode="SameStep"))``, every row stepped in one numpy pass. TorchRL takes a Gymnasium
vector env whose rows reset within the step (``SameStep``, last observations in
``info["final_obs"]`` as Gymnasium's own vector envs put them), so truncated rows bootstrap from
their last observation; :class:`FlattenWithFinals` makes the ``Dict`` observation one vector.

At the end the deterministic policy (and, as the yardstick, uniformly random actions) runs one
episode in each of ``--eval-episodes`` rows of a fresh Gymnasium vector env reset with
``--eval-seed``: fixed targets, the same for both. Needs the ``torchrl`` extra::

    python examples/torchrl_ppo.py --env-kwargs '{"bay": 1, "guide": true}' --total-frames 2000000

``--json`` prints the result as one JSON line. Bad arguments: one line, exit 2.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import gymnasium as gym
import numpy as np
import torch
from torch import nn


class FlattenWithFinals(gym.vector.VectorWrapper):
    """A ``Dict`` observation as one vector, ``info["final_obs"]`` included.

    Gymnasium's vector ``FlattenObservation`` refuses ``SameStep`` envs, whose ``info`` it would
    leave as it is; TorchRL 0.14 cannot read ``Dict`` last observations (nor from Gymnasium's
    own ``SyncVectorEnv``). Keys in the ``Dict`` space's order, as ``gym.spaces.flatten``.
    ``reset`` drops its ``info`` (the targets): TorchRL expects every step to carry the keys it
    saw first.
    """

    def __init__(self, env: gym.vector.VectorEnv) -> None:
        super().__init__(env)
        self.dict_space = env.single_observation_space
        self.single_observation_space = gym.spaces.flatten_space(self.dict_space)
        self.observation_space = gym.vector.utils.batch_space(
            self.single_observation_space, env.num_envs
        )

    @property
    def autoreset_mode(self):
        """The wrapped env's (TorchRL reads it to know where the last observations are)."""
        return self.env.autoreset_mode

    def _flat(self, obs: dict) -> np.ndarray:
        return np.concatenate([obs[k].reshape(self.num_envs, -1) for k in self.dict_space], 1)

    def reset(self, **kwargs):
        """Flattened first observations, no ``info``."""
        obs, _ = self.env.reset(**kwargs)  # (TorchRL wants the step's info keys from reset too)
        return self._flat(obs), {}

    def step(self, actions):
        """Flattened observations, and last observations where rows ended."""
        obs, reward, terminated, truncated, info = self.env.step(actions)
        if "final_obs" in info:
            finals = np.full(self.num_envs, None, dtype=object)
            for i, final in enumerate(info["final_obs"]):
                if final is not None:
                    finals[i] = gym.spaces.flatten(self.dict_space, final)
            info = {**info, "final_obs": finals}
        return self._flat(obs), reward, terminated, truncated, info


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line, checked: a bad value is one line and exit 2 (argparse's ``error``)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--env-kwargs", default="{}", help="keyword arguments of the env, as JSON: '{\"bay\": 1}'"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--total-frames", type=int, default=1_000_000, help="env steps in all")
    parser.add_argument("--num-envs", type=int, default=64, help="rows of the vector env")
    parser.add_argument("--frames-per-batch", type=int, default=4096, help="steps per update")
    parser.add_argument("--minibatch", type=int, default=1024)
    parser.add_argument("--epochs", type=int, default=5)
    parser.add_argument("--learning-rate", type=float, default=3e-4)
    parser.add_argument("--gamma", type=float, default=0.99)
    parser.add_argument("--gae-lambda", type=float, default=0.95)
    parser.add_argument("--clip-epsilon", type=float, default=0.2)
    parser.add_argument("--max-grad-norm", type=float, default=0.5)
    parser.add_argument("--hidden", type=int, default=64, help="units of the two hidden layers")
    parser.add_argument("--eval-episodes", type=int, default=32)
    parser.add_argument("--eval-seed", type=int, default=1_000_000)
    parser.add_argument("--json", action="store_true", help="print the result as one JSON line")
    args = parser.parse_args(argv)
    try:
        args.env_kwargs = json.loads(args.env_kwargs)
    except json.JSONDecodeError as exc:
        parser.error(f"--env-kwargs is not JSON: {exc}")
    if not isinstance(args.env_kwargs, dict):
        parser.error("--env-kwargs must be a JSON object")
    for name in ("total_frames", "num_envs", "frames_per_batch", "minibatch", "epochs"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be at least 1")
    if args.frames_per_batch % args.num_envs:
        parser.error("--frames-per-batch must be a multiple of --num-envs")
    if args.eval_episodes < 1 or args.hidden < 1:
        parser.error("--eval-episodes and --hidden must be at least 1")
    return args


def mlp(n_in: int, n_out: int, hidden: int) -> nn.Sequential:
    """Two tanh hidden layers."""
    return nn.Sequential(
        nn.Linear(n_in, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh(),
        nn.Linear(hidden, n_out),
    )  # fmt: skip


def evaluate(envs: gym.vector.VectorEnv, policy, seed: int) -> tuple[int, int]:
    """(successes, episodes): one episode per row from ``reset(seed=seed)``, first ends only."""
    obs, _ = envs.reset(seed=seed)
    envs.action_space.seed(seed)
    ended = np.zeros(envs.num_envs, dtype=bool)
    success = np.zeros(envs.num_envs, dtype=bool)
    while not ended.all():
        obs, _, terminated, truncated, info = envs.step(policy(obs))
        done = (terminated | truncated) & ~ended
        success |= done & np.asarray(info["is_success"], dtype=bool)
        ended |= done
    return int(success.sum()), envs.num_envs


def main(argv: list[str] | None = None) -> dict:
    """Train, evaluate against random actions, print the result (and return it)."""
    args = parse_args(argv)
    import aftir_rl  # noqa: F401  (registers the ids)
    from aftir_rl.core.errors import AftirError

    try:
        from tensordict import TensorDict
        from tensordict.nn import NormalParamExtractor, TensorDictModule
        from torchrl.collectors import Collector
        from torchrl.data import LazyTensorStorage, ReplayBuffer
        from torchrl.data.replay_buffers import SamplerWithoutReplacement
        from torchrl.envs import GymWrapper
        from torchrl.envs.utils import ExplorationType, set_exploration_type
        from torchrl.modules import ProbabilisticActor, TanhNormal, ValueOperator
        from torchrl.objectives import ClipPPOLoss
        from torchrl.objectives.value import GAE
    except ImportError:
        print("error: TorchRL is not installed: pip install 'aftir_rl[torchrl]'", file=sys.stderr)
        raise SystemExit(2) from None

    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    env_id = "aftir_rl:AFTIR-ArmFTL-v0"
    try:
        venv = gym.make_vec(
            env_id, num_envs=args.num_envs, autoreset_mode="SameStep", **args.env_kwargs
        )
    except (AftirError, TypeError, gym.error.Error) as exc:
        print(f"error: {str(exc).splitlines()[0]}", file=sys.stderr)
        raise SystemExit(2) from None
    env = GymWrapper(FlattenWithFinals(venv))
    env.set_seed(args.seed)
    n_obs = env.observation_spec["observation"].shape[-1]
    n_act = env.action_spec.shape[-1]

    actor_net = nn.Sequential(mlp(n_obs, 2 * n_act, args.hidden), NormalParamExtractor())
    policy = ProbabilisticActor(
        TensorDictModule(actor_net, in_keys=["observation"], out_keys=["loc", "scale"]),
        spec=env.action_spec,
        in_keys=["loc", "scale"],
        distribution_class=TanhNormal,
        distribution_kwargs={"low": -1.0, "high": 1.0},
        return_log_prob=True,
    )
    value = ValueOperator(mlp(n_obs, 1, args.hidden), in_keys=["observation"])
    collector = Collector(
        env,
        policy,
        frames_per_batch=args.frames_per_batch,
        total_frames=args.total_frames,
        split_trajs=False,
        auto_register_policy_transforms=False,  # (this policy keeps no state between steps)
    )
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(args.frames_per_batch),
        sampler=SamplerWithoutReplacement(),
        batch_size=args.minibatch,
    )
    advantage = GAE(gamma=args.gamma, lmbda=args.gae_lambda, value_network=value, average_gae=True)
    loss_module = ClipPPOLoss(
        actor_network=policy,
        critic_network=value,
        clip_epsilon=args.clip_epsilon,
        entropy_bonus=False,
        critic_coeff=0.5,
        loss_critic_type="l2",
    )
    optimizer = torch.optim.Adam(loss_module.parameters(), lr=args.learning_rate)
    frames, start = 0, time.time()
    for data in collector:
        frames += data.numel()
        for _ in range(args.epochs):
            with torch.no_grad():
                advantage(data)
            buffer.extend(data.reshape(-1))
            for _ in range(max(1, args.frames_per_batch // args.minibatch)):
                losses = loss_module(buffer.sample())
                loss = losses["loss_objective"] + losses["loss_critic"]
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(loss_module.parameters(), args.max_grad_norm)
                optimizer.step()
        if not torch.isfinite(loss):
            print(f"error: the loss is no longer finite at frame {frames}", file=sys.stderr)
            raise SystemExit(1)
        collector.update_policy_weights_()
    train_seconds = time.time() - start
    collector.shutdown()
    env.close()

    eval_envs = FlattenWithFinals(
        gym.make_vec(env_id, num_envs=args.eval_episodes, **args.env_kwargs)
    )

    def deterministic(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            batch = TensorDict({"observation": torch.as_tensor(obs)}, batch_size=[len(obs)])
            return policy(batch)["action"].numpy()

    wins, episodes = evaluate(eval_envs, deterministic, args.eval_seed)
    random_wins, _ = evaluate(eval_envs, lambda _: eval_envs.action_space.sample(), args.eval_seed)
    eval_envs.close()
    result = {
        "env_id": "AFTIR-ArmFTL-v0",
        "seed": args.seed,
        "steps": frames,
        "minutes": round(train_seconds / 60, 2),
        "steps_per_second": round(frames / train_seconds),
        "success": wins / episodes,
        "random_success": random_wins / episodes,
        "eval_episodes": episodes,
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(
            f"AFTIR-ArmFTL-v0 (TorchRL PPO): {frames:,} steps in {result['minutes']} min; success "
            f"{wins}/{episodes} deterministic, {random_wins}/{episodes} with random actions"
        )
    return result


if __name__ == "__main__":
    main()
