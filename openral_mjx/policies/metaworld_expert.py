"""`metaworld-expert`: MetaWorld's scripted policy for the scene's task, run in its workers.

MetaWorld's scripted policies (`metaworld.policies`, one per task) are numpy functions of the
39-D observation, importable only in the ``metaworld`` worker environment. Each env worker
already holds that observation, so it computes the policy's action right after every reset and
step and returns it as the observation entry ``expert_action`` (the scene's ``expert``
option, on by default); this policy just plays that entry. No extra process, no extra host
callback per step, the policy runs in parallel over the workers, and the JAX side stays one
pure function (it fuses into the episode's scan like any JAX policy).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax.numpy as jnp

from openral_mjx.core.errors import ConfigError
from openral_mjx.policies.base import Policy

KEY = "expert_action"
SCENE = "metaworld"


def metaworld_expert(scene: Any, arg: str | None) -> Policy:
    """The policy for `scene` (a `metaworld` scene with its ``expert`` option on)."""
    if arg is not None:
        raise ConfigError(f"policy 'metaworld-expert' takes no argument, got :{arg}")
    name = getattr(scene, "name", None)
    if name != SCENE:
        raise ConfigError(
            f"policy 'metaworld-expert' plays MetaWorld's scripted policies: it runs on "
            f"--scene {SCENE}, not {name!r}"
        )
    spec = scene.observation_spec
    if not isinstance(spec, Mapping) or KEY not in spec:
        raise ConfigError(
            "policy 'metaworld-expert' reads the workers' expert action: drop --opt expert=false"
        )

    def init(key, obs_spec):
        del key, obs_spec
        return None, jnp.zeros((), jnp.int32)

    def act(params, pstate, obs, key):
        del params, key
        return jnp.asarray(obs[KEY], jnp.float32), pstate

    return Policy("metaworld-expert", init, act, cache_key="metaworld-expert")
