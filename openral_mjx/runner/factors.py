"""A scene's episode factors per seed (the randomised quantities of each reset, for the
success breakdown), computed beside the episodes with the same device layout."""

from __future__ import annotations

import dataclasses
import weakref
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.runner.device_layout import Layout, PerDevice
from openral_mjx.runner.episode import seed_keys
from openral_mjx.scenes.base import Scene

_FACTOR_STAGES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


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
            s = jax.vmap(scene.traced.reset_with_seed)(seeds, seed_keys(seeds)[0])
            if s.physics is None:  # a host scene: its simulators' state lives in its workers
                return s
            return s.replace(physics=s.physics.replace(data=None))

        # Whether the scene has factors, from one env's reset state (`Scene.state_spec`):
        # most scenes have none, and then no batch of resets is traced.
        stages = None
        if jax.eval_shape(scene.episode_factors, scene.state_spec):
            shape = jax.eval_shape(reset, jax.ShapeDtypeStruct((1,), jnp.int32))
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
