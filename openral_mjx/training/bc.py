"""Behaviour cloning: the scene's scripted expert, rolled out in batch, imitated by an `mlp`.

Demonstrations are the runner's own episodes (`EpisodeRunner` with `obs`/`actions` traces), on
whatever backend the scene runs (MJX on a GPU), keeping the live steps of successful episodes.
The network regresses the expert's action in the `mlp` policy's unit-scaled space (`u`, with
`offset`/`scale` the mean and spread of the expert's actions relative to the joint positions),
on observations normalised by the demonstrations' statistics. The Gaussian's log std is then
set to the log of the per-dimension RMS residual: its maximum-likelihood value given the mean,
and a natural exploration scale for finetuning. It is floored at `min_std` (in `u` units):
where the expert barely moves a joint the residual is tiny, and a near-zero std would make
every policy-gradient step on that joint a huge change in likelihood.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.options import to_dict
from openral_mjx.policies.mlp import MlpConfig, check_architecture, distribution, init_params
from openral_mjx.policies.normalizer import init_stats, update_stats
from openral_mjx.runner import run_seeds
from openral_mjx.scenes.base import Scene


@dataclasses.dataclass(frozen=True)
class Demos:
    """Expert transitions (flattened over episodes and steps) and where they came from."""

    obs: np.ndarray  # (N, obs_size) float32
    actions: np.ndarray  # (N, action_size) float32
    n_episodes: int
    n_successful: int
    env_steps_per_s: float


@dataclasses.dataclass(frozen=True)
class BCConfig:
    """Network and optimisation settings of behaviour cloning."""

    hidden: tuple[int, ...] = (256, 256, 256)
    activation: str = "silu"
    epochs: int = 30
    batch_size: int = 4096
    learning_rate: float = 1e-3
    min_std: float = 0.1
    seed: int = 0

    def __post_init__(self) -> None:
        check_architecture(self.hidden, self.activation)
        for name in ("epochs", "batch_size"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be a positive integer, got {getattr(self, name)}")
        if not self.learning_rate > 0:
            raise ConfigError(f"learning_rate must be > 0, got {self.learning_rate}")


def collect_demos(
    scene: Scene,
    *,
    n_episodes: int,
    n_envs: int,
    max_steps: int,
    first_seed: int = 0,
    successful_only: bool = True,
    on_chunk: Callable[[int, int, int], None] | None = None,
) -> Demos:
    """Roll out the scene's scripted expert on seeds `first_seed ..` and keep its live steps."""
    seeds = np.arange(first_seed, first_seed + n_episodes, dtype=np.int64)
    arrays, timing = run_seeds(
        scene,
        scene.scripted_policy(),
        None,
        seeds=seeds,
        n_envs=n_envs,
        max_steps=max_steps,
        on_chunk=on_chunk,
        record=("obs", "actions"),
    )
    keep = np.arange(max_steps)[None, :] < arrays["steps"][:, None]
    if successful_only:
        keep &= arrays["success"][:, None]
    if not keep.any():
        raise ConfigError(f"the expert succeeded in none of {n_episodes} episodes: no demos")
    return Demos(
        obs=arrays["obs"][keep].astype(np.float32),
        actions=arrays["actions"][keep].astype(np.float32),
        n_episodes=n_episodes,
        n_successful=int(arrays["success"].sum()),
        env_steps_per_s=timing.env_steps / timing.run_s,
    )


def policy_config(scene: Scene, demos: Demos, config: BCConfig) -> MlpConfig:
    """The `mlp` architecture and action mapping fitted to the demonstrations."""
    base_index = scene.action_obs_index()
    delta = demos.actions - (demos.obs[:, list(base_index)] if base_index else 0.0)
    return MlpConfig(
        obs_size=scene.observation_size,
        action_size=scene.action_size,
        action_offset=tuple(float(x) for x in delta.mean(axis=0)),
        action_scale=tuple(float(x) for x in np.maximum(delta.std(axis=0), 1e-3)),
        action_base_index=base_index,
        hidden=tuple(config.hidden),
        activation=config.activation,
        metadata={
            "scene": scene.name,
            "robot": scene.robot_name,
            "scene_options": to_dict(scene.options),
        },
    )


def fit(
    mlp_config: MlpConfig,
    demos: Demos,
    config: BCConfig,
    on_epoch: Callable[[int, float], None] | None = None,
) -> tuple[dict[str, Any], list[float]]:
    """Train the actor by mean-squared error in `u` space; return params and per-epoch losses."""
    obs = jnp.asarray(demos.obs)
    base = np.asarray(mlp_config.action_base_index or [], dtype=np.int64)
    delta = demos.actions - (demos.obs[:, base] if len(base) else 0.0)
    u_target = jnp.asarray(
        (delta - np.asarray(mlp_config.action_offset)) / np.asarray(mlp_config.action_scale),
        jnp.float32,
    )
    n = obs.shape[0]
    batch_size = min(config.batch_size, n)
    n_batches = n // batch_size
    key_init, key_epochs = jax.random.split(jax.random.PRNGKey(config.seed))
    normalizer = update_stats(init_stats(mlp_config.obs_size), obs)
    params = init_params(mlp_config, key_init, normalizer)
    schedule = optax.cosine_decay_schedule(config.learning_rate, config.epochs * n_batches)
    tx = optax.adam(schedule)
    opt_state = tx.init(params["actor"])

    def loss_fn(actor, o, u):
        mean, _ = distribution(mlp_config, {**params, "actor": actor}, o)
        return jnp.mean(jnp.square(mean - u))

    @jax.jit
    def epoch(actor, opt_state, key, obs, u_target):
        perm = jax.random.permutation(key, n)[: n_batches * batch_size]
        batches = (
            obs[perm].reshape(n_batches, batch_size, -1),
            u_target[perm].reshape(n_batches, batch_size, -1),
        )

        def step(carry, batch):
            actor, opt_state = carry
            loss, grads = jax.value_and_grad(loss_fn)(actor, *batch)
            updates, opt_state = tx.update(grads, opt_state, actor)
            return (optax.apply_updates(actor, updates), opt_state), loss

        (actor, opt_state), losses = jax.lax.scan(step, (actor, opt_state), batches)
        return actor, opt_state, losses.mean()

    actor, history = params["actor"], []
    for i in range(config.epochs):
        actor, opt_state, loss = epoch(
            actor, opt_state, jax.random.fold_in(key_epochs, i), obs, u_target
        )
        history.append(float(loss))
        if on_epoch is not None:
            on_epoch(i + 1, history[-1])

    @jax.jit
    def residual_rms(actor, obs, u_target):
        mean, _ = distribution(mlp_config, {**params, "actor": actor}, obs)
        return jnp.sqrt(jnp.mean(jnp.square(mean - u_target), axis=0))

    rms = residual_rms(actor, obs, u_target)
    actor = jax.tree.map(lambda x: x, actor)  # a copy we may edit
    actor["params"]["log_std"] = jnp.log(jnp.maximum(rms, config.min_std))
    return {**params, "actor": actor}, history
