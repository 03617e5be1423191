"""A batch of training envs over a scene: `vmap` outside it, time limit, auto-reset.

Training, unlike evaluation, never stops an env: an episode that ends (success or divergence:
`terminal`; the time limit: `truncated`) is replaced at once by a fresh one. Fresh episodes come
from a pool of reset states drawn once per rollout from new keys (one forward pass per env
per rollout rather than per step); an env that ends twice within one rollout restarts from the
same pool state the second time, which needs an episode shorter than the rollout and is rare.
Training episodes draw their keys from the run's PRNG stream, never from the integer seeds
that evaluation uses (`jax.random.PRNGKey(s)`), so held-out seeds stay held out.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from openral_mjx.runner.refill import per_env_leaves, where_per_env
from openral_mjx.scenes.base import Scene, State


@struct.dataclass
class EnvState:
    """The batch of scene states plus per-env episode bookkeeping."""

    scene: State  # leading axis: env
    t: jax.Array  # (n,) int32: control steps taken in the current episode
    episode_return: jax.Array  # (n,) float32: undiscounted return of the current episode


@struct.dataclass
class StepResult:
    """What one batched step produced, before any env was reset (leading axis: env)."""

    next_obs: jax.Array  # observation after the step (of the ended episode, if it ended)
    reward: jax.Array
    terminal: jax.Array  # bool: ended by the task (success or divergence): no bootstrapping
    done: jax.Array  # bool: ended for any reason, including the time limit
    success: jax.Array  # bool: ended in success
    episode_return: jax.Array  # return of the episode that ended here (0 where not done)


class BatchedEnv:
    """`n_envs` copies of `scene` with a `max_steps` time limit and auto-reset.

    Resetting single envs in place replaces their slice of every per-env state leaf; a leaf
    the batch shares (warp's contact buffer) stays, and the next step rebuilds it, as in the
    evaluator's continuous batching (`runner.refill`).
    """

    def __init__(self, scene: Scene, n_envs: int, max_steps: int) -> None:
        self.scene, self.n_envs, self.max_steps = scene, n_envs, max_steps
        self._per_env = per_env_leaves(scene)

    def reset_states(self, key: jax.Array) -> State:
        """`n_envs` fresh episodes from independent keys split off `key`."""
        return jax.vmap(self.scene.reset)(jax.random.split(key, self.n_envs))

    def reset(self, key: jax.Array) -> EnvState:
        """Fresh episodes, with their step counters spread over the time limit so that time-limit
        resets do not happen to every env at once for the rest of training."""
        k_reset, k_t = jax.random.split(key)
        t = jax.random.randint(k_t, (self.n_envs,), 0, self.max_steps, dtype=jnp.int32)
        zero = jnp.zeros(self.n_envs, jnp.float32)
        return EnvState(scene=self.reset_states(k_reset), t=t, episode_return=zero)

    def step(self, env: EnvState, action: jax.Array, fresh: State) -> tuple[EnvState, StepResult]:
        """Step every env; where an episode ended, continue from `fresh` (a pool of resets)."""
        new = jax.vmap(self.scene.step)(env.scene, action)
        t = env.t + 1
        terminal = new.done
        done = terminal | (t >= self.max_steps)
        ret = env.episode_return + new.reward
        result = StepResult(
            next_obs=new.obs,
            reward=new.reward,
            terminal=terminal,
            done=done,
            success=new.metrics["success"] & done,
            episode_return=jnp.where(done, ret, 0.0),
        )
        env = EnvState(
            scene=where_per_env(done, fresh, new, self._per_env),
            t=jnp.where(done, 0, t),
            episode_return=jnp.where(done, 0.0, ret),
        )
        return env, result
