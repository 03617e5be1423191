"""pick-out-of-hole-v3: lift the peg out of the hole to the goal (MetaWorld 3.1.1).

Draws (peg xyz, goal xyz), redrawn while their xy are closer than 0.15 m (never, with its
box); the peg's free joint goes to the drawn position (velocities zeroed). Observed object: the
``obj`` body's position and ``xquat`` (w-x-y-z). Success: the observed peg within 0.07 of the
goal.

Reward (MetaWorld's v2): the peg caged (grip effort 0.1) times its approach to the goal
(within 0.02), plus 1 + 5 x that approach (kept while the hand stays above a funnel round the
hole) once it is held lifted 2 cm with the gripper not pinched shut; 10 within 0.05 (the base
class's radius: the task's own 0.02 is never read).
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
    tolerance,
)


class PickOutOfHole(FreeObjectTask):
    name = "pick-out-of-hole-v3"
    xml = "sawyer_xyz/sawyer_pick_out_of_hole.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (0.0, 0.75, 0.02, -0.1, 0.5, 0.15)
    reset_high = (0.0, 0.75, 0.02, 0.1, 0.6, 0.3)
    goal_low = (-0.1, 0.5, 0.15)
    goal_high = (0.1, 0.6, 0.3)
    hand_low = (-0.5, 0.40, -0.05)
    hand_high = (0.5, 1.0, 0.5)
    bodies = ("obj", "leftpad", "rightpad")
    success_radius = 0.07
    has_reward = True

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("obj"), view.body_quat("obj")

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        obj, target, start = obs[4:7], episode["target_pos"], episode["obj_init_pos"]
        tcp = view.tcp_center
        to_target = jnp.linalg.norm(obj - target)
        radius = jnp.linalg.norm(tcp[:2] - start[:2])
        floor = jnp.where(
            radius <= 0.03, 0.0, 0.015 * jnp.log(jnp.maximum(radius - 0.03, 1e-30)) + 0.15
        )
        below = tolerance(jnp.maximum(floor - tcp[2], 0.0), 0.01, 0.02)
        above_floor = jnp.where(tcp[2] >= floor, 1.0, below)
        grasped = gripper_caging(view, episode, action, obj, 0.015, 0.02, 0.03, effort=0.1)
        in_place = tolerance(to_target, 0.02, jnp.linalg.norm(start - target))
        reward = hamacher_product(grasped, in_place)
        near = jnp.linalg.norm(obj - tcp) < 0.04
        held = near & (obj[2] - 0.02 > start[2]) & ~(obs[3] < 0.33)
        bonus = 1.0 + 5.0 * hamacher_product(in_place, above_floor)
        reward = jnp.where(held, reward + bonus, reward)
        return jnp.where(to_target < 0.05, 10.0, reward)


TASKS = (PickOutOfHole(),)
