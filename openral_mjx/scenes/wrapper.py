"""`SceneWrapper`: a scene that is another scene with a few members changed.

As brax's and MuJoCo Playground's `Wrapper`, the base forwards the whole `Scene` interface to
`inner`, so a wrapper (e.g. `randomization.Randomized`) overrides only what it changes. The
forwarding is spelled out member by member: `Scene` defines defaults for most of them, and
`__getattr__` only sees names the class lacks, so it covers just the wrapped scene's extras
(scripted-policy helpers, kinematics).

`observation_size` and `observation_spec` are not forwarded: as in `Scene`, they are derived
from this wrapper's own `reset`, so a wrapper that changes the observation needs no override.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import mujoco
import numpy as np

from openral_mjx.scenes.base import RandomizationTargets, Scene, State


def _inner_attr(name: str) -> Any:
    """A read-only property that reads `name` from the wrapped scene (typed `Any` so it may
    stand in for `Scene`'s plain attributes and properties alike)."""
    return property(lambda self: getattr(self.inner, name), doc=f"The wrapped scene's `{name}`.")


class SceneWrapper(Scene):
    """`inner`, unchanged: a subclass overrides the members it changes."""

    def __init__(self, scene: Scene) -> None:
        self.inner = scene

    # What the wrapped scene is: `Scene`'s attributes and properties.
    name = _inner_attr("name")
    task = _inner_attr("task")
    backend = _inner_attr("backend")
    spec = _inner_attr("spec")
    options = _inner_attr("options")
    robot_name = _inner_attr("robot_name")
    sensor_shapes = _inner_attr("sensor_shapes")
    video_camera = _inner_attr("video_camera")
    instruction = _inner_attr("instruction")
    max_steps = _inner_attr("max_steps")
    action_size = _inner_attr("action_size")
    obs_layout = _inner_attr("obs_layout")
    obs_shapes = _inner_attr("obs_shapes")
    control_dt = _inner_attr("control_dt")
    mj_model = _inner_attr("mj_model")

    # What it does: `Scene`'s methods.
    def reset(self, key: jax.Array) -> State:
        return self.inner.reset(key)

    def step(self, state: State, action: jax.Array) -> State:
        return self.inner.step(state, action)

    def reset_with_seed(self, seed: jax.Array, key: jax.Array) -> State:
        return self.inner.reset_with_seed(seed, key)

    def episode_info(self, state: State) -> dict[str, jax.Array]:
        return self.inner.episode_info(state)

    def describe_episode(self, info: dict[str, Any]) -> dict[str, Any]:
        return self.inner.describe_episode(info)

    def prepare(self, n_envs: int) -> None:
        self.inner.prepare(n_envs)

    def close(self) -> None:
        self.inner.close()

    def episode_factors(self, state: State) -> dict[str, jax.Array]:
        return self.inner.episode_factors(state)

    def randomization_targets(self) -> RandomizationTargets | None:
        return self.inner.randomization_targets()

    def cache_parts(self) -> dict[str, Any]:
        return self.inner.cache_parts()

    def frame_record(self, state: State) -> dict[str, jax.Array]:
        return self.inner.frame_record(state)

    def pose_frame(
        self, model: mujoco.MjModel, data: mujoco.MjData, record: Mapping[str, np.ndarray]
    ) -> None:
        self.inner.pose_frame(model, data, record)

    def sensor_frames(self, state: State) -> dict[str, jax.Array]:
        return self.inner.sensor_frames(state)

    def policy_images(self, state: State) -> dict[str, jax.Array]:
        return self.inner.policy_images(state)

    def action_obs_index(self) -> tuple[int, ...] | None:
        return self.inner.action_obs_index()

    def action_bounds(self) -> tuple[jax.Array, jax.Array]:
        return self.inner.action_bounds()

    def __getattr__(self, name: str) -> Any:
        """The wrapped scene's own extras (its scripted policy, kinematics)."""
        if name == "inner":  # not yet set: construction failed early
            raise AttributeError(name)
        return getattr(self.inner, name)
