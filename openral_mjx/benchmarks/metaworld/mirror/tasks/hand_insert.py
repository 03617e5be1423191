"""hand-insert-v3: push the puck into the table's hole (MetaWorld 3.1.1).

Draws (puck xyz, goal xyz), redrawn while their xy are closer than 0.15 m; the puck starts at
the drawn xy and z 0.05 (MetaWorld keeps its init z, which the draw's z equals). Observed
object: the ``obj`` body's position and ``xquat`` (w-x-y-z). Success: the observed puck
within 0.05 of the goal.

Reward (MetaWorld's v2): push-v3's caging of the puck times its approach to the goal, plus
1 + 7 x the approach while the open gripper is within 2 cm of it; 10 on success.
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
    gripper_caging,
    hamacher_product,
    tolerance,
)

OBJ_INIT_Z = 0.05  # init_config["obj_init_pos"][-1]


class HandInsert(FreeObjectTask):
    name = "hand-insert-v3"
    xml = "sawyer_xyz/sawyer_table_with_hole.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.6, 0.05, -0.04, 0.8, -0.0201)
    reset_high = (0.1, 0.7, 0.05, 0.04, 0.88, -0.0199)
    goal_low = (-0.04, 0.8, -0.0201)
    goal_high = (0.04, 0.88, -0.0199)
    hand_low = (-0.5, 0.40, -0.15)
    hand_high = (0.5, 1.0, 0.5)
    bodies = ("obj", "leftpad", "rightpad")
    success_radius = 0.05
    has_reward = True

    def obj_init(self, facts: ModelFacts, vec: jax.Array) -> jax.Array:
        return jnp.concatenate([vec[:2], jnp.full((1,), OBJ_INIT_Z, vec.dtype)])

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("obj"), view.body_quat("obj")

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        obj, target = obs[4:7], episode["target_pos"]
        to_target = jnp.linalg.norm(obj - target)
        in_place = tolerance(to_target, 0.05, jnp.linalg.norm(episode["obj_init_pos"] - target))
        grasped = gripper_caging(view, episode, action, obj, 0.015, 0.05, 0.005)
        reward = hamacher_product(grasped, in_place)
        near = (jnp.linalg.norm(obj - view.tcp_center) < 0.02) & (obs[3] > 0)
        reward = jnp.where(near, reward + 1.0 + 7.0 * in_place, reward)
        return jnp.where(to_target < 0.05, 10.0, reward)


TASKS = (HandInsert(),)
