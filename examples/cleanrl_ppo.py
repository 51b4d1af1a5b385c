"""PPO in one file, CleanRL's way, on any aftir_rl env made by ``gym.make_vec`` alone.

CleanRL's ``ppo_continuous_action.py`` (orthogonal initialisation, separate tanh actor and critic,
a state-independent log-std, GAE, clipped objective and value loss, advantage normalisation per
minibatch, gradient clipping), written against Gymnasium 1.x's vector API:

- the env comes from ``gym.make_vec("aftir_rl:ID", num_envs, **env_kwargs)``; the batched
  ``AFTIR-ArmFTL-v0`` is one process stepping every row (its ``vector_entry_point``), the other
  ids a ``SyncVectorEnv`` of copies;
- ``Dict`` observations are flattened by Gymnasium's vector ``FlattenObservation``, sampled
  actions clipped by its ``ClipAction``;
- the envs reset a finished row on the *next* step (``autoreset_mode`` ``NextStep``): that
  step ignores the row's action and returns its first observation with reward 0, so it is left
  out of the loss; a truncated row's last observation is the step's own next observation, so
  truncation bootstraps from its value and termination does not.

At the end the mean action (and, as the yardstick, uniformly random actions) runs one episode
in each of ``--eval-episodes`` rows of a fresh vector env reset with ``--eval-seed``: fixed
targets, the same for both. Run from the repository (``aftir_rl`` installed)::

    python examples/cleanrl_ppo.py --env-kwargs '{"bay": 1, "guide": true}' \
        --total-timesteps 2000000

``--logdir DIR`` writes TensorBoard scalars under CleanRL's tags (a new directory: an existing
one is refused); ``--json`` prints the result as one JSON line. Bad arguments: one line, exit 2.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.distributions.normal import Normal


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line, checked: a bad value is one line and exit 2 (argparse's ``error``)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--env-id", default="AFTIR-ArmFTL-v0", help="a registered aftir_rl env id")
    parser.add_argument(
        "--env-kwargs", default="{}", help="keyword arguments of the env, as JSON: '{\"bay\": 1}'"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--total-timesteps", type=int, default=1_000_000)
    parser.add_argument("--learning-rate", type=float, default=3e-4)
    parser.add_argument("--num-envs", type=int, default=32, help="rows of the vector env")
    parser.add_argument("--num-steps", type=int, default=64, help="steps per row per update")
    parser.add_argument("--anneal-lr", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--gamma", type=float, default=0.99)
    parser.add_argument("--gae-lambda", type=float, default=0.95)
    parser.add_argument("--num-minibatches", type=int, default=4)
    parser.add_argument("--update-epochs", type=int, default=5)
    parser.add_argument("--clip-coef", type=float, default=0.2)
    parser.add_argument("--ent-coef", type=float, default=0.0)
    parser.add_argument("--vf-coef", type=float, default=0.5)
    parser.add_argument("--max-grad-norm", type=float, default=0.5)
    parser.add_argument("--hidden", type=int, default=64, help="units of the two hidden layers")
    parser.add_argument("--eval-episodes", type=int, default=32)
    parser.add_argument("--eval-seed", type=int, default=1_000_000)
    parser.add_argument("--logdir", type=Path, default=None, help="a new directory for TensorBoard")
    parser.add_argument("--json", action="store_true", help="print the result as one JSON line")
    args = parser.parse_args(argv)
    try:
        args.env_kwargs = json.loads(args.env_kwargs)
    except json.JSONDecodeError as exc:
        parser.error(f"--env-kwargs is not JSON: {exc}")
    if not isinstance(args.env_kwargs, dict):
        parser.error("--env-kwargs must be a JSON object")
    for name in ("total_timesteps", "num_envs", "num_steps", "num_minibatches", "update_epochs"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be at least 1")
    if args.eval_episodes < 1 or args.hidden < 1:
        parser.error("--eval-episodes and --hidden must be at least 1")
    if args.logdir is not None and args.logdir.exists():
        parser.error(f"--logdir {args.logdir} exists: give a new directory")
    return args


def make_env(env_id: str, num_envs: int, env_kwargs: dict) -> gym.vector.VectorEnv:
    """The vector env, flattened and clipped, with episode statistics in ``info``."""
    envs = gym.make_vec(f"aftir_rl:{env_id}", num_envs=num_envs, **env_kwargs)
    if isinstance(envs.single_observation_space, gym.spaces.Dict):
        envs = gym.wrappers.vector.FlattenObservation(envs)
    envs = gym.wrappers.vector.RecordEpisodeStatistics(envs)
    return gym.wrappers.vector.ClipAction(envs)


def layer_init(layer: nn.Linear, std: float = np.sqrt(2), bias_const: float = 0.0) -> nn.Linear:
    """Orthogonal weights of gain ``std``, constant biases (CleanRL's initialisation)."""
    torch.nn.init.orthogonal_(layer.weight, std)
    torch.nn.init.constant_(layer.bias, bias_const)
    return layer


class Agent(nn.Module):
    """Separate tanh MLPs for the value and the action's mean; a learnt log-std per dimension."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: int) -> None:
        super().__init__()
        self.critic = nn.Sequential(
            layer_init(nn.Linear(obs_dim, hidden)),
            nn.Tanh(),
            layer_init(nn.Linear(hidden, hidden)),
            nn.Tanh(),
            layer_init(nn.Linear(hidden, 1), std=1.0),
        )
        self.actor_mean = nn.Sequential(
            layer_init(nn.Linear(obs_dim, hidden)),
            nn.Tanh(),
            layer_init(nn.Linear(hidden, hidden)),
            nn.Tanh(),
            layer_init(nn.Linear(hidden, act_dim), std=0.01),
        )
        self.actor_logstd = nn.Parameter(torch.zeros(1, act_dim))

    def get_value(self, x: torch.Tensor) -> torch.Tensor:
        """The critic's value of each observation."""
        return self.critic(x)

    def get_action_and_value(self, x: torch.Tensor, action: torch.Tensor | None = None):
        """A sampled (or the given) action, its log-probability, the entropy and the value."""
        action_mean = self.actor_mean(x)
        probs = Normal(action_mean, self.actor_logstd.expand_as(action_mean).exp())
        if action is None:
            action = probs.sample()
        return action, probs.log_prob(action).sum(1), probs.entropy().sum(1), self.critic(x)


def evaluate(envs: gym.vector.VectorEnv, policy, seed: int) -> tuple[int, int]:
    """(successes, episodes): one episode per row from ``reset(seed=seed)``, first ends only."""
    obs, _ = envs.reset(seed=seed)
    envs.action_space.seed(seed)
    n = envs.num_envs
    ended = np.zeros(n, dtype=bool)
    success = np.zeros(n, dtype=bool)
    while not ended.all():
        obs, _, terminated, truncated, info = envs.step(policy(obs))
        done = (terminated | truncated) & ~ended
        if "is_success" in info:
            success |= done & np.asarray(info["is_success"], dtype=bool)
        ended |= done
    return int(success.sum()), n


def advantages_and_returns(
    agent: Agent, next_obs: torch.Tensor, buf: dict[str, torch.Tensor], args: argparse.Namespace
) -> tuple[torch.Tensor, torch.Tensor]:
    """GAE: termination cuts the value bootstrap; any end cuts the chain of advantages.

    A truncated row bootstraps from its last observation, which is the next entry (``NextStep``);
    that entry is the reset step, left out of the loss.
    """
    rewards, values = buf["rewards"], buf["values"]
    steps = len(rewards)
    with torch.no_grad():
        next_value = agent.get_value(next_obs).reshape(1, -1)
        advantages = torch.zeros_like(rewards)
        lastgaelam = torch.zeros(rewards.shape[1])
        for t in reversed(range(steps)):
            nextvalues = next_value[0] if t == steps - 1 else values[t + 1]
            delta = rewards[t] + args.gamma * nextvalues * (1.0 - buf["terminated"][t]) - values[t]
            lastgaelam = delta + args.gamma * args.gae_lambda * (1.0 - buf["ended"][t]) * lastgaelam
            advantages[t] = lastgaelam
    return advantages, advantages + values


def ppo_update(
    agent: Agent,
    optimizer: torch.optim.Optimizer,
    batch: dict[str, torch.Tensor],
    args: argparse.Namespace,
) -> dict[str, float]:
    """Clipped policy and value losses over shuffled minibatches, ``update_epochs`` times."""
    b_size = len(batch["obs"])
    minibatch_size = max(1, args.num_envs * args.num_steps // args.num_minibatches)
    b_inds = np.arange(b_size)
    clipfracs = []
    for _epoch in range(args.update_epochs):
        np.random.shuffle(b_inds)
        for begin in range(0, b_size, minibatch_size):
            mb = b_inds[begin : begin + minibatch_size]
            _, newlogprob, entropy, newvalue = agent.get_action_and_value(
                batch["obs"][mb], batch["actions"][mb]
            )
            logratio = newlogprob - batch["logprobs"][mb]
            ratio = logratio.exp()
            with torch.no_grad():
                approx_kl = ((ratio - 1) - logratio).mean()
                clipfracs.append(((ratio - 1.0).abs() > args.clip_coef).float().mean().item())
            mb_advantages = batch["advantages"][mb]
            if len(mb) > 1:
                mb_advantages = (mb_advantages - mb_advantages.mean()) / (
                    mb_advantages.std() + 1e-8
                )
            pg_loss1 = -mb_advantages * ratio
            pg_loss2 = -mb_advantages * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef)
            pg_loss = torch.max(pg_loss1, pg_loss2).mean()
            newvalue = newvalue.view(-1)
            v_loss_unclipped = (newvalue - batch["returns"][mb]) ** 2
            v_clipped = batch["values"][mb] + torch.clamp(
                newvalue - batch["values"][mb], -args.clip_coef, args.clip_coef
            )
            v_loss_clipped = (v_clipped - batch["returns"][mb]) ** 2
            v_loss = 0.5 * torch.max(v_loss_unclipped, v_loss_clipped).mean()
            loss = pg_loss - args.ent_coef * entropy.mean() + v_loss * args.vf_coef
            optimizer.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
            optimizer.step()
    return {
        "loss": loss.item(),
        "losses/value_loss": v_loss.item(),
        "losses/policy_loss": pg_loss.item(),
        "losses/entropy": entropy.mean().item(),
        "losses/approx_kl": approx_kl.item(),
        "losses/clipfrac": float(np.mean(clipfracs)),
    }


def train(
    envs: gym.vector.VectorEnv, args: argparse.Namespace, writer: Any
) -> tuple[Agent, int, float]:
    """PPO for ``total_timesteps``: the agent, the steps taken and the seconds it took."""
    obs_dim = int(np.prod(envs.single_observation_space.shape))
    act_dim = int(np.prod(envs.single_action_space.shape))
    agent = Agent(obs_dim, act_dim, args.hidden)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)
    n, steps = args.num_envs, args.num_steps
    num_iterations = max(1, args.total_timesteps // (n * steps))
    shapes = {"obs": (obs_dim,), "actions": (act_dim,)}
    names = ("obs", "actions", "logprobs", "rewards", "terminated", "ended", "valid", "values")
    buf = {k: torch.zeros((steps, n, *shapes.get(k, ()))) for k in names}

    next_obs = torch.as_tensor(envs.reset(seed=args.seed)[0], dtype=torch.float32)
    envs.action_space.seed(args.seed)
    autoreset = np.zeros(n, dtype=bool)  # rows the next step resets (their action is ignored)
    global_step, start = 0, time.time()
    recent: list[float] = []
    for iteration in range(1, num_iterations + 1):
        if args.anneal_lr:
            frac = 1.0 - (iteration - 1.0) / num_iterations
            optimizer.param_groups[0]["lr"] = frac * args.learning_rate
        for step in range(steps):
            global_step += n
            buf["obs"][step] = next_obs
            buf["valid"][step] = torch.as_tensor(~autoreset, dtype=torch.float32)
            with torch.no_grad():
                action, logprob, _, value = agent.get_action_and_value(next_obs)
            buf["values"][step] = value.flatten()
            buf["actions"][step] = action
            buf["logprobs"][step] = logprob
            next_obs_np, reward, term, trunc, info = envs.step(action.numpy())
            buf["rewards"][step] = torch.as_tensor(reward, dtype=torch.float32)
            buf["terminated"][step] = torch.as_tensor(term, dtype=torch.float32)
            autoreset = term | trunc
            buf["ended"][step] = torch.as_tensor(autoreset, dtype=torch.float32)
            next_obs = torch.as_tensor(next_obs_np, dtype=torch.float32)
            for i in np.flatnonzero(info.get("_episode", ())):
                recent.append(float(info["is_success"][i]) if "is_success" in info else 0.0)
                if writer is not None:
                    writer.add_scalar(
                        "charts/episodic_return", info["episode"]["r"][i], global_step
                    )
                    writer.add_scalar(
                        "charts/episodic_length", info["episode"]["l"][i], global_step
                    )

        advantages, returns = advantages_and_returns(agent, next_obs, buf, args)
        keep = buf["valid"].reshape(-1).bool()
        batch = {k: buf[k].reshape((n * steps, *shapes.get(k, ())))[keep] for k in shapes}
        for k, v in (
            ("logprobs", buf["logprobs"]),
            ("advantages", advantages),
            ("returns", returns),
            ("values", buf["values"]),
        ):
            batch[k] = v.reshape(-1)[keep]
        stats = ppo_update(agent, optimizer, batch, args)
        if not np.isfinite(stats["loss"]):
            print(f"error: the loss is no longer finite at step {global_step}", file=sys.stderr)
            raise SystemExit(1)
        if writer is not None:
            writer.add_scalar("charts/learning_rate", optimizer.param_groups[0]["lr"], global_step)
            for tag, value in stats.items():
                if tag != "loss":
                    writer.add_scalar(tag, value, global_step)
            writer.add_scalar("charts/SPS", int(global_step / (time.time() - start)), global_step)
            if recent:
                writer.add_scalar("charts/success_rate", float(np.mean(recent[-100:])), global_step)
    return agent, global_step, time.time() - start


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Train, evaluate against random actions, print the result (and return it)."""
    args = parse_args(argv)
    import aftir_rl  # noqa: F401  (registers the ids; gym.make_vec's prefix would import it too)
    from aftir_rl.core.errors import AftirError

    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    try:
        envs = make_env(args.env_id, args.num_envs, args.env_kwargs)
    except (AftirError, TypeError, gym.error.Error) as exc:
        print(f"error: {str(exc).splitlines()[0]}", file=sys.stderr)
        raise SystemExit(2) from None
    writer = None
    if args.logdir is not None:
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(str(args.logdir))
        writer.add_text("hyperparameters", json.dumps(vars(args), default=str))
    agent, global_step, train_seconds = train(envs, args, writer)
    envs.close()

    eval_envs = make_env(args.env_id, args.eval_episodes, args.env_kwargs)

    def mean_action(o: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return agent.actor_mean(torch.as_tensor(o, dtype=torch.float32)).numpy()

    def random_action(o: np.ndarray) -> np.ndarray:
        return eval_envs.action_space.sample()

    wins, episodes = evaluate(eval_envs, mean_action, args.eval_seed)
    random_wins, _ = evaluate(eval_envs, random_action, args.eval_seed)
    eval_envs.close()
    result = {
        "env_id": args.env_id,
        "seed": args.seed,
        "steps": global_step,
        "minutes": round(train_seconds / 60, 2),
        "steps_per_second": round(global_step / train_seconds),
        "success": wins / episodes,
        "random_success": random_wins / episodes,
        "eval_episodes": episodes,
    }
    if writer is not None:
        writer.add_scalar("eval/success_rate", result["success"], global_step)
        writer.close()
    if args.json:
        print(json.dumps(result))
    else:
        print(
            f"{args.env_id}: {global_step:,} steps in {result['minutes']} min; success "
            f"{wins}/{episodes} with the mean action, {random_wins}/{episodes} with random actions"
        )
    return result


if __name__ == "__main__":
    main()
