"""`metaworld-expert`: MetaWorld's scripted policy for the scene's task, run in its workers.

On the `metaworld_mjx` mirror, whose observations live in JAX, the same scripted policy runs in
one worker process of the ``metaworld`` environment behind a host callback (`MirrorExpert`):
one call per control step carries the batch's observations there and the actions back.

MetaWorld's scripted policies (`metaworld.policies`, one per task) are numpy functions of the
39-D observation, importable only in the ``metaworld`` worker environment. Each env worker
already holds that observation, so it computes the policy's action right after every reset and
step and returns it as the observation entry ``expert_action`` (the scene's ``expert``
option, on by default); this policy just plays that entry. No extra process, no extra host
callback per step, the policy runs in parallel over the workers, and the JAX side stays one
pure function (it fuses into the episode's scan like any JAX policy).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.host.envs import ensure_env
from openral_mjx.host.pool import Worker, host_callback
from openral_mjx.policies.base import Policy

KEY = "expert_action"
SCENE = "metaworld"
MIRROR = "metaworld_mjx"
ENV = "metaworld"
TIMEOUT_S = 120.0


class MirrorExpert:
    """The host side of the mirror's expert: a worker running MetaWorld's scripted policy."""

    def __init__(self, task: str) -> None:
        self.task = task
        self.worker: Worker | None = None

    def start(self) -> Worker:
        if self.worker is None or not self.worker.alive:
            log = (
                Path(os.environ.get("TMPDIR", "/tmp")) / f"openral_mjx_mw_expert_{os.getpid()}.log"
            )
            self.worker = Worker(ensure_env(ENV), {}, log, name="metaworld expert")
            self.worker.call(
                {
                    "op": "init",
                    "factory": "openral_mjx.benchmarks.metaworld.worker_env:make_expert",
                    "kwargs": {"task": self.task},
                },
                TIMEOUT_S,
            )
        return self.worker

    @host_callback
    def __call__(self, obs: np.ndarray) -> np.ndarray:
        lead = obs.shape[:-1]
        flat = np.asarray(obs, np.float64).reshape(-1, obs.shape[-1])
        out = self.start().call({"op": "call", "method": "act", "kwargs": {"obs": flat}}, TIMEOUT_S)
        return np.asarray(out, np.float32).reshape((*lead, 4))

    def close(self) -> None:
        if self.worker is not None:
            self.worker.close()
            self.worker = None


def _mirror_expert(scene: Any) -> Policy:
    if not scene.options.goal_observable:
        raise ConfigError(
            "policy 'metaworld-expert' reads the goal from the observation on "
            f"--scene {MIRROR}: drop --opt goal_observable=false"
        )
    expert = MirrorExpert(scene.task)
    # MetaWorld's 39 floats; camera images (`obs_rgb_cameras`) follow them.
    start, size = scene.obs_layout["goal"]
    n_state = start + size

    def init(key, obs_spec):
        del key, obs_spec
        return None, jnp.zeros((), jnp.int32)

    def act(params, pstate, obs, key):
        del params, key
        action = jax.pure_callback(
            expert,
            jax.ShapeDtypeStruct((4,), jnp.float32),
            obs[..., :n_state],
            vmap_method="broadcast_all",
        )
        return action, pstate

    return Policy("metaworld-expert", init, act, close=expert.close, per_task=True)


def metaworld_expert(scene: Any, arg: str | None) -> Policy:
    """The policy for `scene` (a `metaworld` scene with its ``expert`` option on)."""
    if arg is not None:
        raise ConfigError(f"policy 'metaworld-expert' takes no argument, got :{arg}")
    name = getattr(scene, "name", None)
    if name == MIRROR:
        return _mirror_expert(scene)
    if name != SCENE:
        raise ConfigError(
            f"policy 'metaworld-expert' plays MetaWorld's scripted policies: it runs on "
            f"--scene {SCENE} or {MIRROR}, not {name!r}"
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
