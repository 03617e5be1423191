"""push-wall-v3, reach-wall-v3: push-v3 and reach-v3 with a wall in the way (MetaWorld 3.1.1).

Both draw (puck xyz, goal xyz), redrawn while their xy are closer than 0.15; the puck's free
joint goes to the drawn position (velocities zeroed). push-wall places the puck at the drawn
xy at the ``objGeom`` geom's rest height (`adjust_initObjPos`), the goal at the drawn xy at that
height; it observes the geom's position. reach-wall places both at the drawn positions and
observes the ``obj`` body's position; both observe the geom's orientation as scipy's
quaternion. Success: push-wall, the observed puck within 0.07 of the goal; reach-wall, the tcp
within 0.05 of the goal (its v2 reward is reach-v3's).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    View,
    gripper_caging,
    matrix_quat,
    tolerance,
)
from openral_mjx.benchmarks.metaworld.mirror.tasks.reach_push_pick import Push, Reach


class PushWall(Push):
    name = "push-wall-v3"
    xml = "sawyer_xyz/sawyer_push_wall_v3.xml"
    reset_low = (-0.05, 0.6, 0.015, -0.05, 0.85, 0.01)
    reset_high = (0.05, 0.65, 0.015, 0.05, 0.9, 0.02)
    goal_low = (-0.05, 0.85, 0.01)
    goal_high = (0.05, 0.9, 0.02)
    # `adjust_initObjPos`: the geom's rest height (body-geom xy offset is zero here)
    rest_key = "geom:objGeom"
    success_radius = 0.07

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.geom_pos("objGeom"), matrix_quat(view.geom_quat("objGeom"))

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: push's, but the puck is led round the wall by a midpoint (x weighted
        3x) before the goal counts."""
        obj, target, start = obs[4:7], episode["target_pos"], episode["obj_init_pos"]
        midpoint = jnp.stack([jnp.asarray(-0.05, obj.dtype), jnp.asarray(0.77, obj.dtype), obj[2]])
        scale = jnp.asarray([3.0, 1.0, 1.0], jnp.float32)
        to_mid = tolerance(
            jnp.linalg.norm((obj - midpoint) * scale),
            0.05,
            jnp.linalg.norm((start - midpoint) * scale),
        )
        to_target = jnp.linalg.norm(obj - target)
        in_place = tolerance(to_target, 0.05, jnp.linalg.norm(start - target))
        grasped = 2.0 * gripper_caging(view, episode, action, obj, 0.015, 0.05, 0.005)
        near = (jnp.linalg.norm(obj - view.tcp_center) < 0.02) & (obs[3] > 0)
        past_wall = obj[1] > 0.75
        past = jnp.where(past_wall, grasped + 5.0 + 3.0 * in_place, grasped + 1.0 + 4.0 * to_mid)
        reward = jnp.where(near, past, grasped)
        return jnp.where(to_target < 0.05, 10.0, reward)


class ReachWall(Reach):
    name = "reach-wall-v3"
    xml = "sawyer_xyz/sawyer_reach_wall_v3.xml"
    reset_low = (-0.05, 0.6, 0.015, -0.05, 0.85, 0.05)
    reset_high = (0.05, 0.65, 0.015, 0.05, 0.9, 0.3)
    goal_low = (-0.05, 0.85, 0.05)
    goal_high = (0.05, 0.9, 0.3)


TASKS = (PushWall(), ReachWall())
