"""The batched episode runner: `vmap` over envs, one `lax.scan` over control steps, one `jit`.

Seed s always maps to `jax.random.PRNGKey(s)`, split into the reset key and the policy's key
stream, so an episode depends on its seed alone: not on batch size, chunking or device.
Finished envs freeze (no auto-reset). More seeds than envs run in chunks of `n_envs` that reuse
one compiled function (the last chunk is padded with extra seeds whose results are dropped).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from openral_mjx.errors import ConfigError
from openral_mjx.policies.base import Policy
from openral_mjx.scenes.base import Scene


@struct.dataclass
class EpisodeArrays:
    """Per-env outcomes of a batch, as arrays (leading axis: env)."""

    success: jax.Array  # bool
    steps: jax.Array  # int32: control steps taken (to success, divergence or max_steps)
    first_success_step: jax.Array  # int32, -1 if never
    total_reward: jax.Array  # float32
    diverged: jax.Array  # bool: non-finite or engine-reset state; never a success


@dataclasses.dataclass(frozen=True)
class RunTiming:
    """Wall-clock measurements of a run (seconds)."""

    compile_s: float
    run_s: float
    chunk_s: tuple[float, ...]
    scan_steps: int
    n_envs: int


def _freeze(done: jax.Array, old: Any, new: Any) -> Any:
    """Keep `old` where an env is already done."""

    def pick(a, b):
        mask = done.reshape(done.shape + (1,) * (a.ndim - done.ndim))
        return jnp.where(mask, a, b)

    return jax.tree.map(pick, old, new)


def make_episode_fn(
    scene: Scene, policy: Policy, max_steps: int, *, record_actions: bool = False
) -> Callable[[Any, jax.Array], EpisodeArrays | tuple[EpisodeArrays, jax.Array]]:
    """A pure function `(policy_params, seeds[n]) -> EpisodeArrays` (jit it).

    With `record_actions`, it also returns the actions taken, `(max_steps, n, action_size)`
    (for benchmarks that replay them open-loop).
    """

    def episode(params: Any, seeds: jax.Array) -> EpisodeArrays:
        keys = jax.vmap(jax.random.PRNGKey)(seeds)
        split = jax.vmap(lambda k: jax.random.split(k, 2))(keys)
        reset_keys, policy_keys = split[:, 0], split[:, 1]
        state = jax.vmap(scene.reset)(reset_keys)
        _, pstate0 = policy.init(
            jax.random.PRNGKey(0), jax.ShapeDtypeStruct(state.obs.shape[1:], state.obs.dtype)
        )
        n = seeds.shape[0]
        pstate = jax.tree.map(lambda x: jnp.broadcast_to(x, (n, *jnp.shape(x))), pstate0)
        acc = EpisodeArrays(
            success=state.metrics["success"],
            steps=jnp.zeros(n, jnp.int32),
            first_success_step=jnp.where(state.metrics["success"], 0, -1).astype(jnp.int32),
            total_reward=jnp.zeros(n, jnp.float32),
            diverged=state.metrics["diverged"],
        )
        done0 = state.done

        def body(carry, t):
            state, pstate, acc, done = carry
            step_keys = jax.vmap(lambda k: jax.random.fold_in(k, t))(policy_keys)
            action, new_pstate = jax.vmap(policy.act, in_axes=(None, 0, 0, 0))(
                params, pstate, state.obs, step_keys
            )
            new_state = jax.vmap(scene.step)(state, action)
            live = ~done
            success = new_state.metrics["success"] & live
            diverged = new_state.metrics["diverged"] & live
            acc = EpisodeArrays(
                success=acc.success | success,
                steps=acc.steps + live.astype(jnp.int32),
                first_success_step=jnp.where(
                    success & (acc.first_success_step < 0), t + 1, acc.first_success_step
                ),
                total_reward=acc.total_reward + jnp.where(live, new_state.reward, 0.0),
                diverged=acc.diverged | diverged,
            )
            new_done = done | new_state.done
            state = _freeze(done, state, new_state)
            pstate = _freeze(done, pstate, new_pstate)
            return (state, pstate, acc, new_done), (action if record_actions else None)

        (_, _, acc, _), actions = jax.lax.scan(
            body, (state, pstate, acc, done0), jnp.arange(max_steps, dtype=jnp.int32)
        )
        return (acc, actions) if record_actions else acc

    return episode


def check_counts(n_envs: int, n_episodes: int, max_steps: int) -> None:
    """Reject non-positive counts with a `ConfigError` naming the value."""
    for name, value in (("n_envs", n_envs), ("n_episodes", n_episodes), ("max_steps", max_steps)):
        if value < 1:
            raise ConfigError(f"{name} must be a positive integer, got {value}")


def run_seeds(
    scene: Scene,
    policy: Policy,
    params: Any,
    *,
    seeds: np.ndarray,
    n_envs: int,
    max_steps: int,
    on_chunk: Callable[[int, int], None] | None = None,
    record_actions: bool = False,
) -> tuple[dict[str, np.ndarray], RunTiming]:
    """Roll out every seed in chunks of `n_envs`; return per-seed numpy arrays and timings.

    The loop runs on the physics backend's JAX device (the CPU for the `c` backend, so a GPU
    machine does not bounce every control step between device and host).
    With `record_actions`, the arrays include `actions`: (n_seeds, max_steps, action_size).

    `on_chunk(done_episodes, total_episodes)` is called once compiled and after each chunk.
    """
    seeds = np.asarray(seeds, dtype=np.int64)
    check_counts(n_envs, len(seeds), max_steps)
    if seeds.min() < 0 or seeds.max() >= 2**31:
        raise ConfigError(f"seeds must lie in [0, 2**31), got range [{seeds.min()}, {seeds.max()}]")
    n_envs = min(n_envs, len(seeds))
    n_chunks = -(-len(seeds) // n_envs)
    padded = np.concatenate([seeds, seeds[-1] + 1 + np.arange(n_chunks * n_envs - len(seeds))])
    padded = np.minimum(padded, 2**31 - 1).astype(np.int32)

    device = scene.backend.jax_device
    fn = jax.jit(make_episode_fn(scene, policy, max_steps, record_actions=record_actions))
    put = (lambda x: jax.device_put(x, device)) if device is not None else jnp.asarray
    params = put(params) if params is not None else None
    t0 = time.perf_counter()
    compiled = fn.lower(params, put(padded[:n_envs])).compile()
    compile_s = time.perf_counter() - t0
    if on_chunk is not None:
        on_chunk(0, len(seeds))

    outs: list[dict[str, np.ndarray]] = []
    chunk_s: list[float] = []
    for c in range(n_chunks):
        t = time.perf_counter()
        out = jax.device_get(compiled(params, put(padded[c * n_envs : (c + 1) * n_envs])))
        chunk_s.append(time.perf_counter() - t)
        acc, actions = out if record_actions else (out, None)
        row = {f.name: np.asarray(getattr(acc, f.name)) for f in dataclasses.fields(acc)}
        if actions is not None:
            row["actions"] = np.swapaxes(np.asarray(actions), 0, 1)
        outs.append(row)
        if on_chunk is not None:
            on_chunk(min((c + 1) * n_envs, len(seeds)), len(seeds))
    merged = {k: np.concatenate([o[k] for o in outs])[: len(seeds)] for k in outs[0]}
    timing = RunTiming(
        compile_s=compile_s,
        run_s=float(sum(chunk_s)),
        chunk_s=tuple(chunk_s),
        scan_steps=max_steps,
        n_envs=n_envs,
    )
    return merged, timing
