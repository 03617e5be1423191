"""The jitted episode: reset a batch of seeds, then one `lax.scan` over control steps.

Seed s always maps to `jax.random.PRNGKey(s)`, split into the reset key and the policy's key
stream, so an episode depends on its seed alone, not on its position in a batch. An episode
ends at success, divergence or the step limit (no auto-reset); the scene handles one env and
the batch is a `vmap` here. Everything in this module is pure JAX, to be jitted by the caller.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct
from jax import export

from openral_mjx.policies.base import Policy
from openral_mjx.scenes.base import Scene, State


@struct.dataclass
class EpisodeArrays:
    """Per-env outcomes of a batch, as arrays (leading axis: env)."""

    success: jax.Array  # bool
    steps: jax.Array  # int32: control steps taken (to success, divergence or max_steps)
    first_success_step: jax.Array  # int32, -1 if never
    total_reward: jax.Array  # float32
    diverged: jax.Array  # bool: non-finite or engine-reset state; never a success
    # bool: diverged because an engine buffer overflowed (contacts, constraints: a capacity to
    # raise), where the backend says (`Quantities.overflowed`); else False
    overflowed: jax.Array
    # Per-step policy latency over the episode's steps (zeros for policies that report none):
    latency_sum_ms: jax.Array  # float32
    latency_max_ms: jax.Array  # float32
    latency_violations: jax.Array  # int32: steps whose latency exceeded the control period
    info: dict[str, jax.Array]  # the scene's `episode_info` of the final state


export.register_pytree_node_serialization(
    EpisodeArrays,
    serialized_name="openral_mjx.runner.EpisodeArrays",
    serialize_auxdata=lambda aux: b"",
    deserialize_auxdata=lambda data: (),
)


def seed_keys(seeds: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Seed s -> (reset key, policy key stream): the two halves of `PRNGKey(s)` split."""
    keys = jax.vmap(jax.random.PRNGKey)(seeds)
    split = jax.vmap(lambda k: jax.random.split(k, 2))(keys)
    return split[:, 0], split[:, 1]


TRACES = ("obs", "actions", "rewards")
StepRecord = Callable[[State, State, jax.Array, jax.Array], Any]


def policy_state0(policy: Policy, obs: Any, n: int) -> Any:
    """The policy's initial state for a batch of `n` envs with observations `obs`."""
    obs_spec = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape[1:], x.dtype), obs)
    _, pstate0 = policy.init(jax.random.PRNGKey(0), obs_spec)
    return jax.tree.map(lambda x: jnp.broadcast_to(x, (n, *jnp.shape(x))), pstate0)


def overflowed(state: State) -> jax.Array:
    """Per env of a batch's `state`, whether an engine buffer overflowed (all False where the
    scene has no physics of ours or its backend no buffers)."""
    flag = getattr(getattr(state.physics, "quantities", None), "overflowed", None)
    return jnp.zeros(state.done.shape, bool) if flag is None else flag


def start_arrays(state: State) -> EpisodeArrays:
    """A batch's episode accumulators at its reset `state` (an episode may end at reset)."""
    n = state.done.shape[0]
    zero = jnp.zeros(n, jnp.float32)
    return EpisodeArrays(
        success=state.metrics["success"],
        steps=jnp.zeros(n, jnp.int32),
        first_success_step=jnp.where(state.metrics["success"], 0, -1).astype(jnp.int32),
        total_reward=zero,
        diverged=state.metrics["diverged"],
        overflowed=state.metrics["diverged"] & overflowed(state),
        latency_sum_ms=zero,
        latency_max_ms=zero,
        latency_violations=jnp.zeros(n, jnp.int32),
        info={},
    )


def control_step(
    scene: Scene,
    policy: Policy,
    params: Any,
    state: State,
    pstate: Any,
    policy_keys: jax.Array,
    t: jax.Array,
    step: Callable[[State, jax.Array], Any] | None = None,
) -> tuple[Any, Any, jax.Array]:
    """One control step of a batch: each env's action from its key stream at its episode step
    `t` (a scalar, or one per env), then the scene's step (or `step`, one env's, vmapped
    here: what it returns takes the state's place). Returns (state, policy state, action)."""
    t = jnp.broadcast_to(t, policy_keys.shape[:1])
    step_keys = jax.vmap(jax.random.fold_in)(policy_keys, t)
    action, new_pstate = jax.vmap(policy.act, in_axes=(None, 0, 0, 0))(
        params, pstate, state.obs, step_keys
    )
    return jax.vmap(step or scene.traced.step)(state, action), new_pstate, action


def accumulate(
    acc: EpisodeArrays,
    new_state: State,
    new_pstate: Any,
    live: jax.Array,
    t: jax.Array,
    policy: Policy,
    budget_ms: float,
) -> EpisodeArrays:
    """The accumulators after the step from episode step `t` to `t + 1`; envs not `live` (their
    episode had already ended) add nothing. A policy with `latency_ms` has its per-step latency
    accumulated over the live steps against the control period `budget_ms`."""
    success = new_state.metrics["success"] & live
    diverged = new_state.metrics["diverged"] & live
    latency = jnp.zeros_like(acc.latency_sum_ms)
    if policy.latency_ms is not None:
        latency = jnp.where(live, jax.vmap(policy.latency_ms)(new_pstate), 0.0)
    return EpisodeArrays(
        success=acc.success | success,
        steps=acc.steps + live.astype(jnp.int32),
        first_success_step=jnp.where(
            success & (acc.first_success_step < 0), t + 1, acc.first_success_step
        ),
        total_reward=acc.total_reward + jnp.where(live, new_state.reward, 0.0),
        diverged=acc.diverged | diverged,
        overflowed=acc.overflowed | (diverged & overflowed(new_state)),
        latency_sum_ms=acc.latency_sum_ms + latency,
        latency_max_ms=jnp.maximum(acc.latency_max_ms, latency),
        latency_violations=acc.latency_violations + (latency > budget_ms),
        info={},
    )


def _episode_scan(
    scene: Scene,
    policy: Policy,
    max_steps: int,
    params: Any,
    seeds: jax.Array,
    record: StepRecord | None,
) -> tuple[EpisodeArrays, State, Any]:
    """Reset a batch of seeds and scan `max_steps` control steps.

    Returns the episode outcomes, the reset state and, per step, `record(state, new_state,
    action, live)` of the batch (the states before and after the step, stacked on a leading
    step axis; None without `record`). `live` is False for envs whose episode had already ended
    before the step.
    """
    reset_keys, policy_keys = seed_keys(seeds)
    state = jax.vmap(scene.traced.reset_with_seed)(seeds, reset_keys)
    pstate = policy_state0(policy, state.obs, seeds.shape[0])
    budget_ms = 1000.0 * scene.control_dt

    def body(carry, t):
        state, pstate, acc, done = carry
        new_state, new_pstate, action = control_step(
            scene, policy, params, state, pstate, policy_keys, t
        )
        live = ~done
        acc = accumulate(acc, new_state, new_pstate, live, t, policy, budget_ms)
        # Finished envs keep simulating in lock-step with the batch, but nothing after their
        # end counts. Freezing them instead would copy the whole physics state every step
        # (~60-115 KB per env on MJX/Warp), which costs more than the physics it saves.
        new_done = done | new_state.done
        out = None if record is None else record(state, new_state, action, live)
        return (new_state, new_pstate, acc, new_done), out

    (last, _, acc, _), records = jax.lax.scan(
        body,
        (state, pstate, start_arrays(state), state.done),
        jnp.arange(max_steps, dtype=jnp.int32),
    )
    return acc.replace(info=jax.vmap(scene.episode_info)(last)), state, records


def make_episode_fn(
    scene: Scene, policy: Policy, max_steps: int, *, record: tuple[str, ...] = ()
) -> Callable[[Any, jax.Array], EpisodeArrays | tuple[EpisodeArrays, dict[str, jax.Array]]]:
    """A pure function `(policy_params, seeds[n]) -> EpisodeArrays` (jit it).

    With `record` (a subset of `TRACES`), it also returns per-step traces, each
    `(max_steps, n, ...)`: `obs`, the observation each action was chosen from, `actions`
    (for demonstrations, and for benchmarks that replay actions open-loop), and `rewards`,
    each step's reward (for reward curves). Steps past an episode's end are recorded too
    (`rewards` as NaN); `EpisodeArrays.steps` says how many count.
    """
    unknown_traces = sorted(set(record) - set(TRACES))
    if unknown_traces:
        raise ValueError(f"unknown traces {unknown_traces}; valid: {', '.join(TRACES)}")

    def traces(state: State, new_state: State, action: jax.Array, live: jax.Array) -> dict:
        every = {
            "obs": lambda: state.obs,
            "actions": lambda: action,
            "rewards": lambda: jnp.where(live, new_state.reward, jnp.nan),
        }
        return {k: every[k]() for k in record}

    def episode(params: Any, seeds: jax.Array) -> Any:
        acc, _, out = _episode_scan(
            scene, policy, max_steps, params, seeds, traces if record else None
        )
        return (acc, out) if record else acc

    return episode


def make_trace_fn(
    scene: Scene, policy: Policy, max_steps: int, n_traced: int
) -> Callable[[Any, jax.Array, jax.Array], tuple[EpisodeArrays, dict[str, Any]]]:
    """The episode function that also records every step of a few envs (for videos).

    `(params, seeds[n], slots[n]) -> (EpisodeArrays[n], trace)`: the env with slot k < n_traced
    fills row k of every `trace` leaf, shaped `(n_traced, max_steps + 1, ...)` with step 0 the
    reset state, behind a leading axis of one (one row per device when run on each device's
    slice: sum them; one device holds each traced env, the others add zeros); other envs have
    slot >= n_traced. The trace holds `frame` (the scene's
    `frame_record`), `images` (its `policy_images`), `sensors` (its `sensor_frames`), `action`
    (that led to the step; zero at step 0), `reward` and `live` (1 while the episode ran, 0
    after its end). Only the traced envs' rows are kept (a scatter per step), so tracing costs
    little memory at any batch size.
    """

    def frame(state: State, action: jax.Array, live: jax.Array) -> dict[str, Any]:
        return {
            "frame": jax.vmap(scene.frame_record)(state),
            "images": jax.vmap(scene.policy_images)(state),
            "sensors": jax.vmap(scene.sensor_frames)(state),
            "action": action,
            "reward": state.reward,
            "live": live.astype(jnp.int32),
        }

    def trace(params: Any, seeds: jax.Array, slots: jax.Array) -> Any:
        def pick(tree: Any) -> Any:
            return jax.tree.map(
                lambda x: (
                    jnp.zeros((n_traced, *x.shape[1:]), x.dtype).at[slots].set(x, mode="drop")
                ),
                tree,
            )

        def record(state: State, new_state: State, action: jax.Array, live: jax.Array) -> Any:
            return pick(frame(new_state, action, live))

        acc, first, records = _episode_scan(scene, policy, max_steps, params, seeds, record)
        n = seeds.shape[0]
        start = pick(frame(first, jnp.zeros((n, scene.action_size)), jnp.ones(n, bool)))
        steps = jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), start, records)
        return acc, jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1)[None], steps)

    return trace
