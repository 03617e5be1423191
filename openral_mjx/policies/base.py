"""The JAX policy contract: two pure functions, so policy and physics fuse into one `lax.scan`.

`init(key, obs_spec) -> (params, policy_state)` runs once per evaluation (params are shared by
all envs; the runner broadcasts `policy_state` to every env). `act(params, policy_state, obs,
key) -> (action, policy_state)` is single-env; the runner vmaps it. A policy that runs outside
JAX (a torch model behind a host callback) measures its own latency per step and exposes it
through `latency_ms(policy_state) -> ms`, which the runner accumulates per episode. A
language-conditioned policy takes the task's natural-language instruction (the scene's
`instruction`) through `instruct(text)`, called before each evaluation (a suite evaluates one
policy on several tasks).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp

InitFn = Callable[[jax.Array, jax.ShapeDtypeStruct], tuple[Any, Any]]
ActFn = Callable[[Any, Any, jax.Array, jax.Array], tuple[jax.Array, Any]]


@dataclasses.dataclass(frozen=True)
class Policy:
    """A named pair of pure functions (see module docstring)."""

    name: str
    init: InitFn
    act: ActFn
    # What, besides the scene and this package's source, decides the code `act` traces to; a
    # traced episode may be reused across runs under it (see `export_cache`). None: never.
    cache_key: str | None = None
    latency_ms: Callable[[Any], jax.Array] | None = None
    close: Callable[[], None] | None = None  # releases host resources (a policy server)
    instruct: Callable[[str], None] | None = None  # sets the task's instruction (VLA policies)
    # Every env of a batch must start its episode at the same step (a policy that keeps one
    # observation history for the whole batch): such a run uses fixed chunks, never refill.
    aligned_episodes: bool = False
    # The policy keeps host-side state for the batch (a torch module behind a callback, a
    # policy server's pipe): the runner gives it one device's batch, never shards running
    # concurrently on several devices.
    one_device: bool = False
    # Built for its scene's task (a task's scripted expert): a suite builds it again for each
    # task rather than sharing it.
    per_task: bool = False

    def devices(self, devices: Sequence[jax.Device]) -> tuple[jax.Device, ...]:
        """The devices a run of this policy uses, of those offered."""
        return tuple(devices)[:1] if self.one_device else tuple(devices)


# call(arrays, t) -> (action, ms): one env's named observation arrays and its control step in
# the episode, to its action and the step's policy latency; a host callback, vmapped over the
# batch as one call ("broadcast_all").
StepCall = Callable[[dict[str, jax.Array], jax.Array], tuple[jax.Array, jax.Array]]


def host_step_policy(
    name: str, call: StepCall, views: Callable[[Any], dict[str, jax.Array]], **fields: Any
) -> Policy:
    """A policy computed outside JAX, one `call` per control step: `views(obs)` names what it
    reads (pure JAX, traced into the episode); its state counts the episode's steps (`t`, so
    the host side sees which envs start an episode) and keeps the step's latency (`ms`).
    `fields`: the other `Policy` fields (`close`, `instruct`, ...)."""

    def init(key, obs_spec):
        del key, obs_spec
        return None, {"t": jnp.zeros((), jnp.int32), "ms": jnp.zeros((), jnp.float32)}

    def act(params, pstate, obs, key):
        del params, key
        action, ms = call(views(obs), pstate["t"])
        return action, {"t": pstate["t"] + 1, "ms": ms}

    return Policy(name, init, act, latency_ms=lambda s: s["ms"], **fields)


def pure_step_call(fn: Callable[..., Any], action_size: int) -> StepCall:
    """`StepCall` through `jax.pure_callback`: `fn(arrays, t)` gets the batch's host arrays
    and returns numpy actions (batch..., action_size) and latencies (batch...)."""
    specs = (
        jax.ShapeDtypeStruct((action_size,), jnp.float32),
        jax.ShapeDtypeStruct((), jnp.float32),
    )

    def call(arrays: dict[str, jax.Array], t: jax.Array) -> tuple[jax.Array, jax.Array]:
        return jax.pure_callback(fn, specs, arrays, t, vmap_method="broadcast_all")

    return call
