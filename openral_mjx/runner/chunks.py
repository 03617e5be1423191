"""Seeds in chunks: the compiled episode run over every requested seed, batch after batch.

More seeds than envs run in chunks of `n_envs` that reuse one compiled function (the last chunk
is padded with extra seeds whose results are dropped). Envs shard over every device the physics
backend runs on (a 1-D mesh over the env axis, each device running the same single-device
program on its slice: see `device_layout`), and a batch that would not fit in device memory is
shrunk before it runs. A caller's `until` predicate, checked after each chunk, can end the run
early (sequential estimation).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import Any

import jax
import numpy as np
from jax.experimental import multihost_utils

from openral_mjx.core.errors import ConfigError
from openral_mjx.policies.base import Policy
from openral_mjx.runner import compile_cache, export_cache
from openral_mjx.runner.device_layout import Layout, Program
from openral_mjx.runner.episode import EpisodeArrays, make_episode_fn
from openral_mjx.runner.factors import factor_stages
from openral_mjx.runner.memory import fit_batch, free_device_bytes, peak_bytes
from openral_mjx.scenes.base import Scene

FACTOR_PREFIX = "factor/"  # run_seeds' key for an episode factor's values
INFO_PREFIX = "info/"  # run_seeds' key for a value of the scene's `episode_info`


def outcome_arrays(acc: EpisodeArrays) -> dict[str, np.ndarray]:
    """`EpisodeArrays` as numpy arrays by field name, `info` entries under `INFO_PREFIX`."""
    names = [f.name for f in dataclasses.fields(acc) if f.name != "info"]
    row = {name: np.asarray(getattr(acc, name)) for name in names}
    row.update({INFO_PREFIX + k: np.asarray(v) for k, v in acc.info.items()})
    return row


@dataclasses.dataclass(frozen=True)
class RunTiming:
    """Wall-clock measurements of a run (seconds) and the batch layout that ran.

    `n_envs` is the batch that ran (the request rounded up to a multiple of the devices, or
    shrunk to fit device memory); `bytes_per_device` is XLA's estimate of the compiled
    episode's peak memory on one device (None where the backend cannot say). A run in chunks
    took `scan_steps` control steps per chunk (`chunk_s` each); a continuously batched run
    (`refill`) took `batch_steps` control steps in all, timed in segments (`chunk_s`), and
    simulated `simulated_steps` env-steps (its batch shrinks as it drains).
    """

    compile_s: float
    run_s: float
    chunk_s: tuple[float, ...]
    scan_steps: int
    n_envs: int
    n_devices: int = 1
    bytes_per_device: int | None = None
    batch_steps: int | None = None
    simulated_steps: int | None = None

    @property
    def env_steps(self) -> int:
        """Env-steps the batch simulated, padding and finished envs included: the machine's
        work, not the episodes' length."""
        if self.simulated_steps is not None:
            return self.simulated_steps
        steps = (
            len(self.chunk_s) * self.scan_steps if self.batch_steps is None else self.batch_steps
        )
        return steps * self.n_envs

    def step_ms(self) -> list[float]:
        """Mean wall time of one batched control step (ms, 4 decimals): per chunk (episode i
        ran in chunk i // n_envs), or one value for a continuously batched run."""
        if self.batch_steps is not None:
            return [round(1000 * self.run_s / max(self.batch_steps, 1), 4)]
        return [round(1000 * s / self.scan_steps, 4) for s in self.chunk_s]


# Upper bounds on what sizes memory, checked before anything is built: a batch of envs (every
# env holds the model's state on the device), the episodes of one report (one result each,
# kept in memory and written one line each) and an episode's control steps (per-step traces).
# 32x the largest run so far (131,072 envs on two H200s); a typo like 1000000000000 is refused
# with a message rather than an allocation traceback.
MAX_ENVS = 2**22
MAX_EPISODES = 2**22
MAX_STEPS = 1_000_000
# Seeds are int32 on the device (`seed_chunks`): every seed of a run lies in [0, 2**31).
SEED_LIMIT = 2**31


def check_counts(n_envs: int, n_episodes: int, max_steps: int) -> None:
    """Reject counts that are not positive or above their bound (`MAX_ENVS`, `MAX_EPISODES`,
    `MAX_STEPS`) with a `ConfigError` naming the value."""
    for name, value, most in (
        ("n_envs", n_envs, MAX_ENVS),
        ("n_episodes", n_episodes, MAX_EPISODES),
        ("max_steps", max_steps, MAX_STEPS),
    ):
        if value < 1:
            raise ConfigError(f"{name} must be a positive integer, got {value}")
        if value > most:
            raise ConfigError(f"{name} must be at most {most:,} (a bound on memory), got {value}")


def check_seeds(seed: int, n_episodes: int = 1, name: str = "seed") -> None:
    """Reject a first seed whose run of `n_episodes` seeds leaves [0, 2**31), with one message
    for every value out of range (negative, 2**32, 2**64, ...)."""
    last = SEED_LIMIT - max(n_episodes, 1)
    if not 0 <= seed <= last:
        span = f" for {n_episodes:,} episodes" if n_episodes > 1 else ""
        raise ConfigError(
            f"{name} must lie in [0, {last}]{span} (seeds are below 2**31), got {seed}"
        )


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
        self.layout = Layout(policy.devices(devices or scene.backend.devices()))
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

    def _checked(self, seeds: np.ndarray) -> np.ndarray:
        """`seeds` as int64, or a `ConfigError` for none, or one outside [0, 2**31)."""
        seeds = np.asarray(seeds, dtype=np.int64)
        check_counts(self.per_device, len(seeds), self.max_steps)
        if seeds.min() < 0 or seeds.max() >= 2**31:
            raise ConfigError(
                f"seeds must lie in [0, 2**31), got range [{seeds.min()}, {seeds.max()}]"
            )
        return seeds

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
                variant=scene.cache_parts(),
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
        need, free = peak_bytes(compiled), free_device_bytes(layout.local_devices[0])
        fitted = fit_batch(self.per_device, need, free, self.memory_fraction)
        if jax.process_count() > 1:  # every process must run the same batch
            fitted = int(np.min(multihost_utils.process_allgather(np.int64(fitted))))
        if fitted != self.per_device:
            self.per_device = fitted
            compiled = self._lower_compile(params)
            need = peak_bytes(compiled)
        self.scene.backend.warm_up()
        self.scene.prepare(self.n_envs)  # host scenes start their workers (not timed as a run)
        self._compiled, self._factor_fn, self._need = compiled, self._compile_factors(), need
        return time.perf_counter() - t0

    def run(
        self,
        params: Any,
        seeds: np.ndarray,
        on_chunk: Callable[[int, int, int], None] | None = None,
        until: Callable[[dict[str, Any]], bool] | None = None,
    ) -> tuple[dict[str, Any], RunTiming]:
        """Roll out every seed; return per-seed numpy arrays and timings (`compile_s` is 0 once
        compiled).

        The arrays are the `EpisodeArrays` fields by name (see `outcome_arrays`), per factor the
        scene declares (see `make_factor_fn`) its values under `FACTOR_PREFIX + name`, and the
        recorded traces as `(n_seeds, max_steps, ...)`.

        `on_chunk(done_episodes, total_episodes, successes)` is called once compiled and after
        each chunk (`successes` among the `done_episodes` first seeds: a running rate).
        `until(arrays_so_far)`, if given, is called after each chunk; when it returns True no
        further chunk runs and only the seeds run so far are returned. The chunk size is fixed
        before any episode runs (it depends on the devices and memory, never on outcomes).
        """
        seeds = self._checked(seeds)
        layout = self.layout
        params = layout.put_replicated(params) if params is not None else None
        compile_s = self._compile(params) if self._compiled is None else 0.0
        n_envs = self.n_envs
        chunks = seed_chunks(seeds, n_envs)
        n_chunks = len(chunks)
        if on_chunk is not None:
            on_chunk(0, len(seeds), 0)
        successes = 0

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
            successes += int(row["success"][: done - c * n_envs].sum())
            if on_chunk is not None:
                on_chunk(done, len(seeds), successes)
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
