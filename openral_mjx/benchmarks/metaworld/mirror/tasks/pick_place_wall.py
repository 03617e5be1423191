"""pick-place-wall-v3: carry the puck over the wall to the goal (MetaWorld 3.1.1).

Draws (puck xyz, goal xyz), redrawn while their xy are closer than 0.15 m; the puck's free
joint goes to the drawn position (velocities zeroed). Observed object: the ``objGeom`` geom's
position and orientation as scipy's quaternion (x-y-z-w). Success: the observed puck within
0.07 of the goal.

Reward (MetaWorld's v2): the puck caged and gripped (low density) times its approach to a
point over the wall (z weighted 3x); held lifted 1.5 cm, plus 1 + 4 x that approach, or once
past the wall (y > 0.75) 1 + 4 + 3 x the approach to the goal; 10 within 0.05.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    FreeObjectTask,
    View,
    gripper_caging,
    hamacher_product,
    matrix_quat,
    tolerance,
)


class PickPlaceWall(FreeObjectTask):
    name = "pick-place-wall-v3"
    xml = "sawyer_xyz/sawyer_pick_place_wall_v3.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.05, 0.6, 0.015, -0.05, 0.85, 0.05)
    reset_high = (0.05, 0.65, 0.015, 0.05, 0.9, 0.3)
    goal_low = (-0.05, 0.85, 0.05)
    goal_high = (0.05, 0.9, 0.3)
    bodies = ("leftpad", "rightpad")
    geoms = ("objGeom",)
    success_radius = 0.07
    has_reward = True

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.geom_pos("objGeom"), matrix_quat(view.geom_quat("objGeom"))

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        obj, target, start = obs[4:7], episode["target_pos"], episode["obj_init_pos"]
        midpoint = jnp.stack(
            [target[0], jnp.asarray(0.77, obj.dtype), jnp.asarray(0.25, obj.dtype)]
        )
        scale = jnp.asarray([1.0, 1.0, 3.0], jnp.float32)
        over = tolerance(
            jnp.linalg.norm((obj - midpoint) * scale),
            0.05,
            jnp.linalg.norm((start - midpoint) * scale),
        )
        to_target = jnp.linalg.norm(obj - target)
        in_place = tolerance(to_target, 0.05, jnp.linalg.norm(start - target))
        grasped = gripper_caging(view, episode, action, obj, 0.015, 0.05, 0.005, density="low")
        reward = hamacher_product(grasped, over)
        near = jnp.linalg.norm(obj - view.tcp_center) < 0.02
        held = near & (obs[3] > 0) & (obj[2] - 0.015 > start[2])
        carried = jnp.where(obj[1] > 0.75, reward + 5.0 + 3.0 * in_place, reward + 1.0 + 4.0 * over)
        reward = jnp.where(held, carried, reward)
        return jnp.where(to_target < 0.05, 10.0, reward)


TASKS = (PickPlaceWall(),)
