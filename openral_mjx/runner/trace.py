"""Re-running chosen seeds with every step of their episodes recorded (videos, sensor frames)."""

from __future__ import annotations

import weakref
from collections.abc import Callable, Sequence
from typing import Any

import jax
import numpy as np

from openral_mjx.policies.base import Policy
from openral_mjx.runner.chunks import envs_per_device, outcome_arrays, seed_chunks
from openral_mjx.runner.device_layout import Layout
from openral_mjx.runner.episode import make_trace_fn
from openral_mjx.scenes.base import Scene

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
    layout = Layout(policy.devices(devices or scene.backend.devices()))
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
