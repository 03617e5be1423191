"""shelf-place-v3: put the block on the shelf (MetaWorld 3.1.1).

Draws (block xyz, goal xyz), redrawn while their xy are closer than 0.1. The ``shelf`` body goes
to the goal lowered by 0.3; the goal is the ``goal`` site's model position (in the shelf's
frame) plus the shelf's, i.e. the drawn goal. The block's free joint goes to the drawn xy at
the ``obj`` body's rest height (velocities zeroed). Observed object: the ``obj`` body's position
and the ``objGeom`` geom's orientation as scipy's quaternion. Success: the observed block within
0.07 of the goal.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    FreeObjectTask,
    ModelFacts,
    View,
    at_rest_height,
    gripper_caging,
    hamacher_product,
    matrix_quat,
    tolerance,
)

SHELF_DROP = (0.0, 0.0, 0.3)


class ShelfPlace(FreeObjectTask):
    name = "shelf-place-v3"
    xml = "sawyer_xyz/sawyer_shelf_placing.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.5, 0.019, -0.1, 0.8, 0.299)
    reset_high = (0.1, 0.6, 0.021, 0.1, 0.9, 0.301)
    goal_low = (-0.1, 0.8, 0.299)
    goal_high = (0.1, 0.9, 0.301)
    bodies = ("obj", "leftpad", "rightpad")
    has_reward = True
    geoms = ("objGeom",)
    moved_bodies = ("shelf",)
    min_goal_distance = 0.1
    success_radius = 0.07

    def obj_init(self, facts: ModelFacts, vec: jax.Array) -> jax.Array:
        return at_rest_height(facts, vec[:2], "body:obj", vec.dtype)

    def _shelf(self, vec: jax.Array) -> jax.Array:
        return vec[3:6] - jnp.asarray(SHELF_DROP, vec.dtype)

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos, qvel, _ = super().place(facts, vec, qpos, qvel)
        return qpos, qvel, {"shelf": self._shelf(vec)}

    def target(self, facts: ModelFacts, vec: jax.Array, view: View) -> jax.Array:
        return jnp.asarray(facts.site_pos["goal"], vec.dtype) + self._shelf(vec)

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("obj"), matrix_quat(view.geom_quat("objGeom"))

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: the block caged and gripped (low density) times its approach to
        the goal; while held lifted, plus 1 + 5 x that approach, which fades in front of and
        under the shelf and is 0 behind it; 10 within 0.05."""
        obj, target, start = obs[4:7], episode["target_pos"], episode["obj_init_pos"]
        to_target = jnp.linalg.norm(obj - target)
        in_place = tolerance(to_target, 0.05, jnp.linalg.norm(start - target))
        grasped = gripper_caging(view, episode, action, obj, 0.02, 0.05, 0.01, density="low")
        reward = hamacher_product(grasped, in_place)
        low = (obj[2] > 0.0) & (obj[2] < 0.24)
        beside = (obj[0] > target[0] - 0.15) & (obj[0] < target[0] + 0.15)
        front = (obj[1] > target[1] - 0.15) & (obj[1] < target[1])
        z_scaling = (0.24 - obj[2]) / 0.24
        y_scaling = (obj[1] - (target[1] - 0.15)) / 0.15
        faded = jnp.clip(in_place - hamacher_product(y_scaling, z_scaling), 0.0, 1.0)
        in_place = jnp.where(low & beside & front, faded, in_place)
        in_place = jnp.where(low & beside & (obj[1] > target[1]), 0.0, in_place)
        near = jnp.linalg.norm(obj - view.tcp_center) < 0.025
        held = near & (obs[3] > 0) & (obj[2] - 0.01 > start[2])
        reward = jnp.where(held, reward + 1.0 + 5.0 * in_place, reward)
        return jnp.where(to_target < 0.05, 10.0, reward)


TASKS = (ShelfPlace(),)
