"""`run_seeds`: roll out every seed once, with either way of batching them.

`chunks` runs fixed batches of `n_envs` seeds, each for the full episode length; `refill`
(continuous batching) hands a slot the next seed as soon as its episode ends, so the batch does
not simulate finished episodes. Per seed, both give the same episode (bit for bit on `c`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import jax
import numpy as np

from openral_mjx.policies.base import Policy
from openral_mjx.runner.chunks import EpisodeRunner, RunTiming, check_counts
from openral_mjx.runner.refill import RefillRunner, check_batching, resolve_batching
from openral_mjx.scenes.base import Scene


def make_runner(
    scene: Scene,
    policy: Policy,
    *,
    n_envs: int,
    max_steps: int,
    batching: str = "chunks",
    refill_every: int = 1,
    record: tuple[str, ...] = (),
    memory_fraction: float = 0.85,
    devices: Sequence[jax.Device] | None = None,
) -> EpisodeRunner:
    """The runner for `batching` (`chunks`, `refill`, or `auto`: `refill` where it applies);
    traces (`record`) need `chunks`."""
    aligned = policy.aligned_episodes
    check_batching(batching, scene.backend.name, refill_every, bool(record), aligned)
    backend = scene.backend.name
    if resolve_batching(batching, backend, None, n_envs, bool(record), aligned) == "chunks":
        return EpisodeRunner(
            scene,
            policy,
            n_envs=n_envs,
            max_steps=max_steps,
            record=record,
            memory_fraction=memory_fraction,
            devices=devices,
        )
    return RefillRunner(
        scene,
        policy,
        n_envs=n_envs,
        max_steps=max_steps,
        refill_every=refill_every,
        memory_fraction=memory_fraction,
        devices=devices,
    )


def run_seeds(
    scene: Scene,
    policy: Policy,
    params: Any,
    *,
    seeds: np.ndarray,
    n_envs: int,
    max_steps: int,
    on_chunk: Callable[[int, int, int], None] | None = None,
    record: tuple[str, ...] = (),
    memory_fraction: float = 0.85,
    devices: Sequence[jax.Device] | None = None,
    until: Callable[[dict[str, Any]], bool] | None = None,
    batching: str = "chunks",
    refill_every: int = 1,
) -> tuple[dict[str, Any], RunTiming]:
    """Roll out every seed once with `min(n_envs, len(seeds))` envs at a time (see
    `EpisodeRunner` and `RefillRunner`; `auto` batching: see `resolve_batching`)."""
    check_counts(n_envs, len(seeds), max_steps)
    aligned = policy.aligned_episodes
    check_batching(batching, scene.backend.name, refill_every, bool(record), aligned)
    runner = make_runner(
        scene,
        policy,
        n_envs=min(n_envs, len(seeds)),
        max_steps=max_steps,
        batching=resolve_batching(
            batching, scene.backend.name, len(seeds), n_envs, bool(record), aligned
        ),
        refill_every=refill_every,
        record=record,
        memory_fraction=memory_fraction,
        devices=devices,
    )
    return runner.run(params, seeds, on_chunk, until)
