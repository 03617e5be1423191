"""Baselines that should mostly fail: hold every actuator at 0, or act uniformly at random."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from openral_mjx.policies.base import Policy


def _no_params(key: jax.Array, obs_spec: jax.ShapeDtypeStruct) -> tuple[None, jax.Array]:
    del key, obs_spec
    return None, jnp.zeros((), jnp.int32)


def zero_policy(action_size: int) -> Policy:
    """Action 0 for every actuator (for position servos: drive to the zero pose)."""

    def act(params, pstate, obs, key):
        del params, obs, key
        return jnp.zeros(action_size, jnp.float32), pstate

    return Policy("zero", _no_params, act, cache_key="zero")


def random_policy(low: jax.Array, high: jax.Array) -> Policy:
    """A fresh uniform sample within the actuator limits at every step."""

    def act(params, pstate, obs, key):
        del params, obs
        return jax.random.uniform(key, low.shape, minval=low, maxval=high), pstate

    return Policy("random", _no_params, act, cache_key="random")
