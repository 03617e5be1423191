"""PPO (clipped surrogate, GAE) on optax and brax's PPO pieces: one jitted function per update,
all state a pytree.

An update rolls the batch of training envs forward `unroll_length` steps with the Gaussian
`mlp` policy (sampling), computes advantages with GAE, then takes `n_epochs` passes of
minibatch Adam steps on the actor (the `mlp` policy's params) and a separate critic MLP.
Everything an update reads is in `TrainState` (params, optimiser states, observation
normaliser, env states, PRNG key, update count), so saving it and restoring it continues a run
exactly: update `u` draws its randomness from `fold_in(key, u)`, not from a key chain.

Choices, and why:
* The training reward is the scene's reward plus `success_bonus` on the step an episode
  succeeds (which ends it). Scene rewards are dense shaping (distances); a small success term
  leaves PPO improving the distances without finishing the task, while evaluation counts
  successes only. The scene's reward, and what evaluation reports, stay unchanged.
* Time limits bootstrap: at a truncated step the advantage uses the critic's value of the
  observation the episode ended on (computed before the reset), not of the next episode's.
* The actor is frozen for the first `critic_warmup` updates, so a critic starting from random
  weights does not drag a pretrained (behaviour-cloned) actor around with noise.
* The actor's learning rate adapts to keep the KL divergence from the rollout policy near
  `target_kl` (as in rsl_rl's adaptive schedule): a finetuned policy must not jump away from
  its pretrained behaviour on one batch, and a fixed rate that suits one scale of network and
  batch does not suit another.
* The normaliser's statistics are updated after each update's gradient steps, from that
  update's observations; the rollout and the loss of one update see the same normalisation.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax
from brax.training.agents.ppo.losses import compute_gae
from brax.training.distribution import NormalDistribution
from flax import struct

from openral_mjx.core.errors import ConfigError
from openral_mjx.policies.mlp import MlpConfig, distribution, normalized_obs, to_action
from openral_mjx.policies.normalizer import update_stats
from openral_mjx.scenes.base import Scene
from openral_mjx.training.env import BatchedEnv, EnvState


@dataclasses.dataclass(frozen=True)
class PPOConfig:
    """PPO hyperparameters (defaults sized for thousands of envs on one GPU)."""

    n_envs: int = 4096
    unroll_length: int = 16
    n_minibatches: int = 8
    n_epochs: int = 4
    actor_lr: float = 3e-5
    critic_lr: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_eps: float = 0.2
    entropy_coef: float = 0.0
    max_grad_norm: float = 1.0
    critic_warmup: int = 5
    target_kl: float = 0.01
    reward_scale: float = 1.0
    success_bonus: float = 10.0
    critic_hidden: tuple[int, ...] = (256, 256, 256)
    max_steps: int = 200
    update_normalizer: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("n_envs", "unroll_length", "n_minibatches", "n_epochs", "max_steps"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be a positive integer, got {getattr(self, name)}")
        batch = self.n_envs * self.unroll_length
        if batch % self.n_minibatches:
            raise ConfigError(
                f"n_envs x unroll_length = {batch} does not split into "
                f"{self.n_minibatches} equal minibatches"
            )
        names = ("actor_lr", "critic_lr", "clip_eps", "max_grad_norm", "reward_scale")
        for name in names:
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("gamma", "gae_lambda"):
            if not 0 <= getattr(self, name) <= 1:
                raise ConfigError(f"{name} must lie in [0, 1], got {getattr(self, name)}")
        for name in ("critic_warmup", "entropy_coef", "target_kl", "success_bonus"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{name} must be >= 0, got {getattr(self, name)}")

    @property
    def steps_per_update(self) -> int:
        return self.n_envs * self.unroll_length


class Critic(nn.Module):
    """Normalised observation -> state value."""

    hidden: tuple[int, ...]

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for size in self.hidden:
            x = nn.silu(nn.Dense(size)(x))
        return nn.Dense(1)(x)[..., 0]


@struct.dataclass
class TrainState:
    """Everything a PPO update reads and writes."""

    policy: dict[str, Any]  # the `mlp` policy's params: {"actor", "normalizer"}
    critic: Any
    actor_opt: Any
    critic_opt: Any
    env: EnvState
    key: jax.Array  # the run's key; update u uses fold_in(key, u)
    update: jax.Array  # () int32: updates done


@struct.dataclass
class Batch:
    """One update's transitions (leading axes: time, env; flattened for the minibatches)."""

    obs: jax.Array
    u: jax.Array
    logp: jax.Array
    advantage: jax.Array
    target: jax.Array  # value target: advantage + value


_GAUSSIAN = NormalDistribution(event_size=1)  # brax's Normal; the event size is unused here


def gaussian_logp(u: jax.Array, mean: jax.Array, log_std: jax.Array) -> jax.Array:
    """Log density of `u` under the diagonal Gaussian (brax's `NormalDistribution`), summed
    over the action axis."""
    return _GAUSSIAN.log_prob((mean, jnp.exp(log_std)), u)


def gae(
    reward: jax.Array,
    value: jax.Array,
    next_value: jax.Array,
    terminal: jax.Array,
    done: jax.Array,
    gamma: float,
    lam: float,
) -> jax.Array:
    """Generalised advantage estimates over a `(T, n)` rollout, by brax's `compute_gae`.

    `next_value[t]` is the value of the observation step t led to, before any reset; it is
    dropped where the episode ended by the task (`terminal`), and the recursion is cut at every
    episode end (`done`). brax instead bootstraps step t from the next row (`value[t+1]`, a
    fresh episode after a reset) and zeroes truncated steps. Adding the difference to the
    reward, `r_t + gamma ((1 - terminal_t) next_value_t - (1 - done_t) value_{t+1})`, and
    passing every end as a termination makes brax's recursion this one (up to rounding).
    """
    value_next_row = jnp.concatenate([value[1:], next_value[-1:]], axis=0)
    keep = 1.0 - done
    reward = reward + gamma * ((1.0 - terminal) * next_value - keep * value_next_row)
    vs, _ = compute_gae(
        truncation=jnp.zeros_like(done),
        termination=done,
        rewards=reward,
        values=value,
        bootstrap_value=next_value[-1],
        lambda_=lam,
        discount=gamma,
    )
    return vs - value


def _optimizer(lr: float, max_grad_norm: float) -> optax.GradientTransformation:
    """Adam after global-norm clipping, its learning rate kept in the state (adapted by KL)."""

    def make(learning_rate):
        return optax.chain(optax.clip_by_global_norm(max_grad_norm), optax.adam(learning_rate))

    return optax.inject_hyperparams(make)(learning_rate=lr)


def _adapt_lr(opt_state: Any, kl: jax.Array, target: float) -> Any:
    """Divide the learning rate by 1.5 when the KL from the rollout policy exceeds twice
    `target`, multiply it by 1.5 below half of it (within [1e-6, 1e-2]); 0 turns this off."""
    if target <= 0:
        return opt_state
    lr = opt_state.hyperparams["learning_rate"]
    lr = jnp.where(kl > 2 * target, lr / 1.5, jnp.where(kl < target / 2, lr * 1.5, lr))
    hyper = {**opt_state.hyperparams, "learning_rate": jnp.clip(lr, 1e-6, 1e-2)}
    return opt_state._replace(hyperparams=hyper)


class PPO:
    """PPO for `scene` with an `mlp` actor of `mlp_config`. `init`/`update` are pure; jit them."""

    def __init__(self, scene: Scene, mlp_config: MlpConfig, config: PPOConfig) -> None:
        if (mlp_config.obs_size, mlp_config.action_size) != (
            scene.observation_size,
            scene.action_size,
        ):
            raise ConfigError(
                f"policy sizes (obs {mlp_config.obs_size}, action {mlp_config.action_size}) do "
                f"not match scene {scene.name!r} ({scene.observation_size}, {scene.action_size})"
            )
        self.mlp, self.config = mlp_config, config
        self.env = BatchedEnv(scene, config.n_envs, config.max_steps)
        self.critic = Critic(tuple(config.critic_hidden))
        self.actor_tx = _optimizer(config.actor_lr, config.max_grad_norm)
        self.critic_tx = _optimizer(config.critic_lr, config.max_grad_norm)

    # ---- state -----------------------------------------------------------------------------

    def init(self, policy_params: dict[str, Any]) -> TrainState:
        """A new run from `policy_params` (e.g. a clone): fresh critic, envs and optimisers."""
        key_init, key_run = jax.random.split(jax.random.PRNGKey(self.config.seed))
        key_critic, key_env = jax.random.split(key_init)
        obs = jnp.zeros(self.mlp.obs_size, jnp.float32)
        critic = self.critic.init(key_critic, obs)
        return TrainState(
            policy=policy_params,
            critic=critic,
            actor_opt=self.actor_tx.init(policy_params["actor"]),
            critic_opt=self.critic_tx.init(critic),
            env=self.env.reset(key_env),
            key=key_run,
            update=jnp.zeros((), jnp.int32),
        )

    def _value(self, critic: Any, policy: dict[str, Any], obs: jax.Array) -> jax.Array:
        return self.critic.apply(critic, normalized_obs(self.mlp, policy, obs))

    # ---- one update ------------------------------------------------------------------------

    def _rollout(self, ts: TrainState, key: jax.Array) -> tuple[EnvState, dict[str, jax.Array]]:
        key_pool, key_act = jax.random.split(key)
        fresh = self.env.reset_states(key_pool)

        def step(env: EnvState, t: jax.Array):
            obs = env.scene.obs
            mean, log_std = distribution(self.mlp, ts.policy, obs)
            noise = jax.random.normal(jax.random.fold_in(key_act, t), mean.shape)
            u = mean + jnp.exp(log_std) * noise
            value = self._value(ts.critic, ts.policy, obs)
            env, res = self.env.step(env, to_action(self.mlp, obs, u), fresh)
            record = {
                "obs": obs,
                "u": u,
                "logp": gaussian_logp(u, mean, log_std),
                "value": value,
                "next_value": self._value(ts.critic, ts.policy, res.next_obs),
                "reward": res.reward,
                "terminal": res.terminal.astype(jnp.float32),
                "done": res.done.astype(jnp.float32),
                "success": res.success.astype(jnp.float32),
                "episode_return": res.episode_return,
            }
            return env, record

        steps = jnp.arange(self.config.unroll_length, dtype=jnp.int32)
        return jax.lax.scan(step, ts.env, steps)

    def _loss(self, trainable: dict[str, Any], ts: TrainState, batch: Batch):
        c = self.config
        policy = {**ts.policy, "actor": trainable["actor"]}
        mean, log_std = distribution(self.mlp, policy, batch.obs)
        logp = gaussian_logp(batch.u, mean, log_std)
        log_ratio = logp - batch.logp
        ratio = jnp.exp(log_ratio)
        adv = batch.advantage
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        clipped = jnp.clip(ratio, 1 - c.clip_eps, 1 + c.clip_eps)
        policy_loss = -jnp.mean(jnp.minimum(ratio * adv, clipped * adv))
        entropy = jnp.sum(log_std + 0.5 * math.log(2 * math.pi * math.e))
        value = self._value(trainable["critic"], ts.policy, batch.obs)
        value_loss = 0.5 * jnp.mean(jnp.square(value - batch.target))
        loss = policy_loss - c.entropy_coef * entropy + value_loss
        stats = {
            "policy_loss": policy_loss,
            "value_loss": value_loss,
            "entropy": entropy,
            "approx_kl": jnp.mean(ratio - 1 - log_ratio),
            "clip_fraction": jnp.mean((jnp.abs(ratio - 1) > c.clip_eps).astype(jnp.float32)),
        }
        return loss, stats

    def update(self, ts: TrainState) -> tuple[TrainState, dict[str, jax.Array]]:
        """One PPO update: rollout, advantages, `n_epochs` of minibatch steps, normaliser."""
        c = self.config
        key_rollout, key_sgd = jax.random.split(jax.random.fold_in(ts.key, ts.update))
        env, tr = self._rollout(ts, key_rollout)
        reward = tr["reward"] * c.reward_scale + c.success_bonus * tr["success"]
        adv = gae(
            reward, tr["value"], tr["next_value"], tr["terminal"], tr["done"], c.gamma, c.gae_lambda
        )
        n = c.steps_per_update
        batch = Batch(
            obs=tr["obs"].reshape(n, -1),
            u=tr["u"].reshape(n, -1),
            logp=tr["logp"].reshape(n),
            advantage=adv.reshape(n),
            target=(adv + tr["value"]).reshape(n),
        )
        train_actor = ts.update >= c.critic_warmup
        grad_fn = jax.grad(self._loss, has_aux=True)

        def minibatch(carry, mb: Batch):
            actor, critic, actor_opt, critic_opt = carry
            grads, stats = grad_fn({"actor": actor, "critic": critic}, ts, mb)
            upd, new_actor_opt = self.actor_tx.update(grads["actor"], actor_opt, actor)
            new_actor = optax.apply_updates(actor, upd)
            new_actor_opt = _adapt_lr(new_actor_opt, stats["approx_kl"], c.target_kl)
            # Frozen actor: keep params and optimiser state (Adam's step count included).
            actor, actor_opt = jax.tree.map(
                lambda new, old: jnp.where(train_actor, new, old),
                (new_actor, new_actor_opt),
                (actor, actor_opt),
            )
            upd, critic_opt = self.critic_tx.update(grads["critic"], critic_opt, critic)
            critic = optax.apply_updates(critic, upd)
            return (actor, critic, actor_opt, critic_opt), stats

        def epoch(carry, key):
            perm = jax.random.permutation(key, n)
            shuffled = jax.tree.map(
                lambda x: x[perm].reshape(c.n_minibatches, n // c.n_minibatches, *x.shape[1:]),
                batch,
            )
            return jax.lax.scan(minibatch, carry, shuffled)

        carry = (ts.policy["actor"], ts.critic, ts.actor_opt, ts.critic_opt)
        (actor, critic, actor_opt, critic_opt), stats = jax.lax.scan(
            epoch, carry, jax.random.split(key_sgd, c.n_epochs)
        )
        normalizer = ts.policy["normalizer"]
        if c.update_normalizer:
            normalizer = update_stats(normalizer, tr["obs"])
        new = ts.replace(
            policy={"actor": actor, "normalizer": normalizer},
            critic=critic,
            actor_opt=actor_opt,
            critic_opt=critic_opt,
            env=env,
            update=ts.update + 1,
        )
        episodes = tr["done"].sum()
        target = batch.target
        residual = target - tr["value"].reshape(n)
        metrics = {
            **jax.tree.map(jnp.mean, stats),
            "reward": tr["reward"].mean(),
            "episodes": episodes,
            "successes": tr["success"].sum(),
            "episode_return": tr["episode_return"].sum() / jnp.maximum(episodes, 1.0),
            "std": jnp.exp(actor["params"]["log_std"]).mean(),
            "explained_variance": 1.0 - residual.var() / (target.var() + 1e-8),
            "actor_trained": train_actor.astype(jnp.float32),
            "actor_lr": actor_opt.hyperparams["learning_rate"],
        }
        return new, metrics
