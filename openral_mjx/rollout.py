"""The batched episode runner: `vmap` over envs, one `lax.scan` over control steps, one `jit`.

Seed s always maps to `jax.random.PRNGKey(s)`, split into the reset key and the policy's key
stream, so an episode depends on its seed alone, not on its position in a batch. An episode
ends at success, divergence or the step limit (no auto-reset). More seeds than envs run in
chunks of `n_envs` that reuse one compiled function (the last chunk is padded with extra seeds
whose results are dropped). Envs shard over every device the physics backend runs on (a 1-D
mesh over the env axis, each device running the same single-device program on its slice: see
`device_layout`), and a batch that would not fit in device memory is shrunk before it runs. A
caller's `until` predicate, checked after each chunk, can end the run early (sequential
estimation).
"""

from __future__ import annotations

import dataclasses
import time
import weakref
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from jax import export
from jax.experimental import multihost_utils

from openral_mjx import compile_cache, export_cache
from openral_mjx.device_layout import Layout, PerDevice, Program
from openral_mjx.errors import ConfigError
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
    # Per-step policy latency over the episode's steps (zeros for policies that report none):
    latency_sum_ms: jax.Array  # float32
    latency_max_ms: jax.Array  # float32
    latency_violations: jax.Array  # int32: steps whose latency exceeded the control period
    info: dict[str, jax.Array]  # the scene's `episode_info` of the final state


export.register_pytree_node_serialization(
    EpisodeArrays,
    serialized_name="openral_mjx.rollout.EpisodeArrays",
    serialize_auxdata=lambda aux: b"",
    deserialize_auxdata=lambda data: (),
)


@dataclasses.dataclass(frozen=True)
class RunTiming:
    """Wall-clock measurements of a run (seconds) and the batch layout that ran.

    `n_envs` is the batch that ran (the request rounded up to a multiple of the devices, or
    shrunk to fit device memory); `bytes_per_device` is XLA's estimate of the compiled
    episode's peak memory on one device (None where the backend cannot say).
    """

    compile_s: float
    run_s: float
    chunk_s: tuple[float, ...]
    scan_steps: int
    n_envs: int
    n_devices: int = 1
    bytes_per_device: int | None = None


def seed_keys(seeds: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Seed s -> (reset key, policy key stream): the two halves of `PRNGKey(s)` split."""
    keys = jax.vmap(jax.random.PRNGKey)(seeds)
    split = jax.vmap(lambda k: jax.random.split(k, 2))(keys)
    return split[:, 0], split[:, 1]


TRACES = ("obs", "actions", "rewards")
StepRecord = Callable[[State, State, jax.Array, jax.Array], Any]


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
    before the step. A policy with `latency_ms` has its per-step latency accumulated over each
    episode's live steps against the control period.
    """
    reset_keys, policy_keys = seed_keys(seeds)
    state = jax.vmap(scene.reset_with_seed)(seeds, reset_keys)
    obs_spec = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape[1:], x.dtype), state.obs)
    _, pstate0 = policy.init(jax.random.PRNGKey(0), obs_spec)
    n = seeds.shape[0]
    pstate = jax.tree.map(lambda x: jnp.broadcast_to(x, (n, *jnp.shape(x))), pstate0)
    zero = jnp.zeros(n, jnp.float32)
    budget_ms = 1000.0 * scene.control_dt
    acc = EpisodeArrays(
        success=state.metrics["success"],
        steps=jnp.zeros(n, jnp.int32),
        first_success_step=jnp.where(state.metrics["success"], 0, -1).astype(jnp.int32),
        total_reward=zero,
        diverged=state.metrics["diverged"],
        latency_sum_ms=zero,
        latency_max_ms=zero,
        latency_violations=jnp.zeros(n, jnp.int32),
        info={},
    )

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
        latency = jnp.zeros_like(acc.latency_sum_ms)
        if policy.latency_ms is not None:
            latency = jnp.where(live, jax.vmap(policy.latency_ms)(new_pstate), 0.0)
        acc = EpisodeArrays(
            success=acc.success | success,
            steps=acc.steps + live.astype(jnp.int32),
            first_success_step=jnp.where(
                success & (acc.first_success_step < 0), t + 1, acc.first_success_step
            ),
            total_reward=acc.total_reward + jnp.where(live, new_state.reward, 0.0),
            diverged=acc.diverged | diverged,
            latency_sum_ms=acc.latency_sum_ms + latency,
            latency_max_ms=jnp.maximum(acc.latency_max_ms, latency),
            latency_violations=acc.latency_violations + (latency > budget_ms),
            info={},
        )
        # Finished envs keep simulating in lock-step with the batch, but nothing after their
        # end counts. Freezing them instead would copy the whole physics state every step
        # (~60-115 KB per env on MJX/Warp), which costs more than the physics it saves.
        new_done = done | new_state.done
        out = None if record is None else record(state, new_state, action, live)
        return (new_state, new_pstate, acc, new_done), out

    (last, _, acc, _), records = jax.lax.scan(
        body, (state, pstate, acc, state.done), jnp.arange(max_steps, dtype=jnp.int32)
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


def check_counts(n_envs: int, n_episodes: int, max_steps: int) -> None:
    """Reject non-positive counts with a `ConfigError` naming the value."""
    for name, value in (("n_envs", n_envs), ("n_episodes", n_episodes), ("max_steps", max_steps)):
        if value < 1:
            raise ConfigError(f"{name} must be a positive integer, got {value}")


_FACTOR_STAGES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
FACTOR_PREFIX = "factor/"  # run_seeds' key for an episode factor's values
INFO_PREFIX = "info/"  # run_seeds' key for a value of the scene's `episode_info`


def outcome_arrays(acc: EpisodeArrays) -> dict[str, np.ndarray]:
    """`EpisodeArrays` as numpy arrays by field name, `info` entries under `INFO_PREFIX`."""
    names = [f.name for f in dataclasses.fields(acc) if f.name != "info"]
    row = {name: np.asarray(getattr(acc, name)) for name in names}
    row.update({INFO_PREFIX + k: np.asarray(v) for k, v in acc.info.items()})
    return row


@dataclasses.dataclass(frozen=True)
class FactorStages:
    """The two jitted halves of a scene's `episode_factors` over seeds (see `make_factor_fn`):
    `reset(seeds) -> leaves` of the reset state, then `factors(leaves) -> {name: values}`.
    The state crosses as a flat list of arrays so each half can be exported and cached."""

    reset: PerDevice  # seeds -> list of arrays
    factors: PerDevice  # list of arrays -> {name: values}


def factor_stages(scene: Scene, devices: Sequence[jax.Device] | None = None) -> FactorStages | None:
    """The scene's factor stages sharded over `devices`; None when it declares no factors.
    Cached per scene and devices, so the compiled functions are reused."""
    layout = Layout(tuple(devices or scene.backend.devices()))
    cache = _FACTOR_STAGES.setdefault(scene, {})
    if layout.devices not in cache:

        def reset(seeds: jax.Array) -> Any:
            s = jax.vmap(scene.reset_with_seed)(seeds, seed_keys(seeds)[0])
            if s.physics is None:  # a host scene: its simulators' state lives in its workers
                return s
            return s.replace(physics=s.physics.replace(data=None))

        shape = jax.eval_shape(reset, jax.ShapeDtypeStruct((1,), jnp.int32))
        stages = None
        if jax.eval_shape(jax.vmap(scene.episode_factors), shape):
            treedef = jax.tree.structure(shape)
            stages = FactorStages(
                reset=layout.per_device(lambda seeds: jax.tree.leaves(reset(seeds))),
                factors=layout.per_device(
                    lambda leaves: jax.vmap(scene.episode_factors)(
                        jax.tree.unflatten(treedef, leaves)
                    )
                ),
            )
        cache[layout.devices] = stages
    return cache[layout.devices]


def make_factor_fn(
    scene: Scene, devices: Sequence[jax.Device] | None = None
) -> Callable[[jax.Array], dict[str, jax.Array]] | None:
    """`seeds[n] -> {factor: values[n]}`: the scene's `episode_factors` of each seed's reset
    state, sharded like the episodes; None when the scene declares no factors.

    The factors see the reset state without the backend's raw data (they read quantities,
    `info`, `obs`, `metrics`, as all task logic does). Two jitted functions, reset then
    factors, not one: inside one XLA fusion the reset's arithmetic is recomputed and contracted
    (a * b + c into an FMA) differently at different batch sizes, which changed factors in the
    last bit with the batch size; reading the materialised reset state keeps them bit-identical.
    """
    stages = factor_stages(scene, devices)
    if stages is None:
        return None
    return lambda seeds: stages.factors(stages.reset(seeds))


def _peak_bytes(compiled: Any) -> int | None:
    """XLA's estimate of a compiled function's device memory (arguments, outputs, scratch)."""
    try:
        m = compiled.memory_analysis()
    except Exception:  # not every backend implements it
        return None
    if m is None:
        return None
    return int(m.temp_size_in_bytes + m.argument_size_in_bytes + m.output_size_in_bytes)


def free_device_bytes(device: jax.Device) -> int | None:
    """Bytes the device's allocator can still hand out (None on backends that do not say)."""
    stats = device.memory_stats() or {}
    if "bytes_limit" not in stats:
        return None
    return int(stats["bytes_limit"] - stats.get("bytes_in_use", 0))


def _fit_batch(per_device: int, need: int | None, free: int | None, fraction: float) -> int:
    """The per-device batch that fits `fraction` of `free` bytes, given that `per_device` envs
    need `need` bytes (memory grows ~linearly with envs); a multiple of 64 when that large."""
    if need is None or free is None or need <= fraction * free:
        return per_device
    target = int(per_device * fraction * free / need)
    return max(1, target // 64 * 64 if target >= 64 else target)


def envs_per_device(n_envs: int, n_devices: int, limit: int | None = None) -> int:
    """Envs each device runs for a batch of `n_envs`: rounded up, and at least two (within
    the backend's `limit`). XLA compiles a batch of one as scalar code whose fused arithmetic
    (FMA contraction) can differ in the last bit from batched code: two envs per device keep
    seed s's episode identical whether it runs alone or in a batch."""
    return max(-(-n_envs // n_devices), min(2, limit or 2))


def seed_chunks(seeds: np.ndarray, n_envs: int) -> np.ndarray:
    """The batches `run_seeds` runs, `(n_chunks, n_envs)` int32: the seeds in order, the last
    chunk padded with the seeds that follow the last one (their results are dropped)."""
    seeds = np.asarray(seeds, np.int64)
    n_chunks = -(-len(seeds) // n_envs)
    padded = np.concatenate([seeds, seeds[-1] + 1 + np.arange(n_chunks * n_envs - len(seeds))])
    return np.minimum(padded, 2**31 - 1).astype(np.int32).reshape(n_chunks, n_envs)


class EpisodeRunner:
    """Rolls out seeds in chunks of `n_envs`, compiled once and kept across `run` calls.

    A training loop evaluates new params on held-out seeds without recompiling. The loop runs
    on the physics backend's devices (the host CPU for `c`, so a GPU machine does not bounce
    every control step between device and host; every GPU for `mjx`/`warp`). `n_envs` is
    rounded up to a multiple of the device count (and to two envs per device); if the compiled
    batch would need more than
    `memory_fraction` of a device's free memory, it is shrunk (and recompiled) to fit, and
    `RunTiming.n_envs` says what ran. `devices` overrides the backend's choice (e.g. a subset
    of the GPUs).
    """

    def __init__(
        self,
        scene: Scene,
        policy: Policy,
        *,
        n_envs: int,
        max_steps: int,
        record: tuple[str, ...] = (),
        memory_fraction: float = 0.85,
        devices: Sequence[jax.Device] | None = None,
    ) -> None:
        check_counts(n_envs, 1, max_steps)
        self.scene = scene
        self.layout = Layout(tuple(devices or scene.backend.devices()))
        limit = scene.backend.max_batch
        self.per_device = envs_per_device(n_envs, len(self.layout.devices), limit)
        if limit is not None and self.per_device > limit:
            raise ConfigError(
                f"{self.per_device} envs per device exceed the {scene.backend.name} backend's "
                f"buffers (sized for batch_size={limit}); build the scene with a larger batch_size"
            )
        self.policy = policy
        self.max_steps, self.record, self.memory_fraction = max_steps, record, memory_fraction
        self._fn = self.layout.per_device(
            make_episode_fn(scene, policy, max_steps, record=record),
            (0, {k: 1 for k in record}) if record else 0,  # traces are (steps, envs, ...)
        )
        self._compiled: Any = None
        self._factor_fn: Callable | None = None
        self._need: int | None = None

    @property
    def n_envs(self) -> int:
        """The batch that runs (final once compiled: it may shrink to fit in memory)."""
        return self.per_device * len(self.layout.devices)

    def _lower(
        self, program: str, fn: Callable, args: tuple, cacheable: bool = True, **parts: Any
    ) -> Any:
        """`fn.lower(*args)` through the export cache, keyed by `program`, the scene, its
        backend and devices, `parts` and the arguments; uncached where the backend has host
        callbacks (they cannot be serialized) or the caller says it is not `cacheable`."""
        scene, key, device = self.scene, None, self.layout.devices[0]
        if cacheable and scene.backend.exportable:
            key = export_cache.cache_key(
                program=program,
                scene=[type(scene).__module__, type(scene).__qualname__, scene.name],
                options=dataclasses.asdict(scene.options),
                model=export_cache.model_digest(scene.mj_model),
                backend=scene.backend.describe(),
                device=[device.platform, device.device_kind],
                args=export_cache.argument_signature(args),
                **parts,
            )
        return export_cache.lower(fn, args, key, compile_cache.export_dir())

    def _lower_compile(self, params: Any) -> Program:
        """The compiled episode; cached across processes only for a policy that says what
        determines its code (`Policy.cache_key`)."""
        args = (params, self.layout.put_envs(np.zeros(self.n_envs, np.int32)))
        policy = self.policy
        return self._fn.compile(
            args,
            lambda fn, local_args: self._lower(
                "episode",
                fn,
                local_args,
                cacheable=policy.cache_key is not None,
                policy=policy.cache_key,
                max_steps=self.max_steps,
                record=list(self.record),
            ),
        )

    def _compile_factors(self) -> Callable[[jax.Array], dict[str, jax.Array]] | None:
        """The compiled factor stages (see `make_factor_fn`), run once so no chunk pays for
        them; None when the scene declares no factors."""
        stages = factor_stages(self.scene, self.layout.devices)
        if stages is None:
            return None
        seeds = self.layout.put_envs(np.zeros(self.n_envs, np.int32))
        reset = stages.reset.compile((seeds,), lambda fn, a: self._lower("factor-reset", fn, a))
        leaves = reset(seeds)
        factors = stages.factors.compile((leaves,), lambda fn, a: self._lower("factors", fn, a))
        jax.block_until_ready(factors(leaves))
        return lambda chunk: factors(reset(chunk))

    def _compile(self, params: Any) -> float:
        layout, t0 = self.layout, time.perf_counter()
        compiled = self._lower_compile(params)
        need, free = _peak_bytes(compiled), free_device_bytes(layout.local_devices[0])
        fitted = _fit_batch(self.per_device, need, free, self.memory_fraction)
        if jax.process_count() > 1:  # every process must run the same batch
            fitted = int(np.min(multihost_utils.process_allgather(np.int64(fitted))))
        if fitted != self.per_device:
            self.per_device = fitted
            compiled = self._lower_compile(params)
            need = _peak_bytes(compiled)
        self.scene.backend.warm_up()
        self.scene.prepare(self.n_envs)  # host scenes start their workers (not timed as a run)
        self._compiled, self._factor_fn, self._need = compiled, self._compile_factors(), need
        return time.perf_counter() - t0

    def run(
        self,
        params: Any,
        seeds: np.ndarray,
        on_chunk: Callable[[int, int], None] | None = None,
        until: Callable[[dict[str, Any]], bool] | None = None,
    ) -> tuple[dict[str, Any], RunTiming]:
        """Roll out every seed; return per-seed numpy arrays and timings (`compile_s` is 0 once
        compiled).

        The arrays are the `EpisodeArrays` fields by name (see `outcome_arrays`), per factor the
        scene declares (see `make_factor_fn`) its values under `FACTOR_PREFIX + name`, and the
        recorded traces as `(n_seeds, max_steps, ...)`.

        `on_chunk(done_episodes, total_episodes)` is called once compiled and after each chunk.
        `until(arrays_so_far)`, if given, is called after each chunk; when it returns True no
        further chunk runs and only the seeds run so far are returned. The chunk size is fixed
        before any episode runs (it depends on the devices and memory, never on outcomes).
        """
        seeds = np.asarray(seeds, dtype=np.int64)
        check_counts(self.per_device, len(seeds), self.max_steps)
        if seeds.min() < 0 or seeds.max() >= 2**31:
            raise ConfigError(
                f"seeds must lie in [0, 2**31), got range [{seeds.min()}, {seeds.max()}]"
            )
        layout = self.layout
        params = layout.put_replicated(params) if params is not None else None
        compile_s = self._compile(params) if self._compiled is None else 0.0
        n_envs = self.n_envs
        chunks = seed_chunks(seeds, n_envs)
        n_chunks = len(chunks)
        if on_chunk is not None:
            on_chunk(0, len(seeds))

        outs: list[dict[str, Any]] = []
        chunk_s: list[float] = []
        merged: dict[str, Any] = {}
        for c in range(n_chunks):
            t = time.perf_counter()
            chunk = layout.put_envs(chunks[c])
            out = layout.get(self._compiled(params, chunk))
            factors = {} if self._factor_fn is None else layout.get(self._factor_fn(chunk))
            chunk_s.append(time.perf_counter() - t)
            acc, traces = out if self.record else (out, {})
            row = outcome_arrays(acc)
            row.update({FACTOR_PREFIX + k: np.asarray(v) for k, v in factors.items()})
            row.update({k: np.swapaxes(np.asarray(v), 0, 1) for k, v in traces.items()})
            outs.append(row)
            done = min((c + 1) * n_envs, len(seeds))
            if on_chunk is not None:
                on_chunk(done, len(seeds))
            if until is not None or c == n_chunks - 1:
                merged = {k: np.concatenate([o[k] for o in outs])[:done] for k in outs[0]}
                if until is not None and until(merged):
                    break
        timing = RunTiming(
            compile_s=compile_s,
            run_s=float(sum(chunk_s)),
            chunk_s=tuple(chunk_s),
            scan_steps=self.max_steps,
            n_envs=n_envs,
            n_devices=len(layout.devices),
            bytes_per_device=self._need,
        )
        return merged, timing


def run_seeds(
    scene: Scene,
    policy: Policy,
    params: Any,
    *,
    seeds: np.ndarray,
    n_envs: int,
    max_steps: int,
    on_chunk: Callable[[int, int], None] | None = None,
    record: tuple[str, ...] = (),
    memory_fraction: float = 0.85,
    devices: Sequence[jax.Device] | None = None,
    until: Callable[[dict[str, Any]], bool] | None = None,
) -> tuple[dict[str, Any], RunTiming]:
    """Roll out every seed once, in chunks of `min(n_envs, len(seeds))` (see `EpisodeRunner`)."""
    check_counts(n_envs, len(seeds), max_steps)
    runner = EpisodeRunner(
        scene,
        policy,
        n_envs=min(n_envs, len(seeds)),
        max_steps=max_steps,
        record=record,
        memory_fraction=memory_fraction,
        devices=devices,
    )
    return runner.run(params, seeds, on_chunk, until)


_TRACE_FNS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def trace_seeds(
    scene: Scene,
    policy: Policy,
    params: Any,
    *,
    seeds: Sequence[int],
    max_steps: int,
    batch_of: Callable[[int], np.ndarray] | None = None,
    devices: Sequence[jax.Device] | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Re-run `seeds` and record every step of their episodes (see `make_trace_fn`).

    Each seed runs inside the batch `batch_of(seed)` (e.g. the chunk it ran in during an
    evaluation, for backends whose episodes depend on the batch layout); by default the traced
    seeds run together as one batch (enough where a seed's episode is the same in any batch).
    Returns the traced episodes' outcomes (`EpisodeArrays` fields, one entry per seed, in the
    order given) and their trace (numpy leaves `(len(seeds), max_steps + 1, ...)`).
    """
    seeds = [int(s) for s in seeds]
    layout = Layout(tuple(devices or scene.backend.devices()))
    n_dev = len(layout.devices)
    groups: dict[bytes, tuple[np.ndarray, list[int]]] = {}
    for i, seed in enumerate(seeds):
        batch = np.asarray(sorted(set(seeds)) if batch_of is None else batch_of(seed), np.int64)
        if not (batch == seed).any():
            raise ValueError(f"seed {seed} is not in the batch it should run in")
        groups.setdefault(batch.tobytes(), (batch, []))[1].append(i)
    n_traced = max(len(rows) for _, rows in groups.values())
    key = (policy, max_steps, n_traced, layout.devices)
    cache = _TRACE_FNS.setdefault(scene, {})
    if key not in cache:
        cache[key] = layout.per_device(make_trace_fn(scene, policy, max_steps, n_traced))
    fn = cache[key]
    params = layout.put_replicated(params) if params is not None else None
    outcomes: list[Any] = [None] * len(seeds)
    traces: list[Any] = [None] * len(seeds)
    for batch, rows in groups.values():
        padded = seed_chunks(batch, envs_per_device(len(batch), n_dev) * n_dev)[0]
        slots = np.full(len(padded), n_traced, np.int32)
        for slot, i in enumerate(rows):
            slots[int(np.flatnonzero(padded == seeds[i])[0])] = slot
        acc, trace = layout.get(fn(params, layout.put_envs(padded), layout.put_envs(slots)))
        trace = jax.tree.map(lambda x: np.sum(x, axis=0), trace)  # one row per device
        for slot, i in enumerate(rows):
            position = int(np.flatnonzero(slots == slot)[0])
            outcomes[i] = jax.tree.map(lambda x, p=position: np.asarray(x)[p], acc)
            traces[i] = jax.tree.map(lambda x, k=slot: np.asarray(x)[k], trace)
    arrays = outcome_arrays(jax.tree.map(lambda *xs: np.stack(xs), *outcomes))
    return arrays, jax.tree.map(lambda *xs: np.stack(xs), *traces)
