"""push-back-v3: push the puck back towards the robot (MetaWorld 3.1.1).

Draws (puck xyz, goal xyz); the goal is the drawn xy at the ``objGeom`` geom's rest height
(`adjust_initObjPos`), redrawn while the puck's and the goal's xy are closer than 0.15. The
puck's free joint goes to the drawn xy at that height (velocities zeroed). Observed object: the
geom's position and orientation as scipy's quaternion (x-y-z-w). Success: the observed puck
within 0.07 of the goal.
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
    hamacher_product,
    matrix_quat,
    pushing_caging,
    tolerance,
)


class PushBack(FreeObjectTask):
    name = "push-back-v3"
    xml = "sawyer_xyz/sawyer_push_back_v3.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.8, 0.02, -0.1, 0.6, 0.0199)
    reset_high = (0.1, 0.85, 0.02, 0.1, 0.7, 0.0201)
    goal_low = (-0.1, 0.6, 0.0199)
    goal_high = (0.1, 0.7, 0.0201)
    bodies = ("leftpad", "rightpad")
    geoms = ("objGeom",)
    success_radius = 0.07
    has_reward = True

    def obj_init(self, facts: ModelFacts, vec: jax.Array) -> jax.Array:
        return at_rest_height(facts, vec[:2], "geom:objGeom", vec.dtype)

    def target(self, facts: ModelFacts, vec: jax.Array, view: View) -> jax.Array:
        return at_rest_height(facts, vec[3:5], "geom:objGeom", vec.dtype)

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.geom_pos("objGeom"), matrix_quat(view.geom_quat("objGeom"))

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: the puck caged (its own caging) times its approach to the goal,
        plus 1 and 5x that approach while the tcp touches it in a half-closed grip having
        moved it 1 cm closer; 10 within 0.05."""
        obj, target = obs[4:7], episode["target_pos"]
        to_target = jnp.linalg.norm(obj - target)
        init = jnp.linalg.norm(episode["obj_init_pos"] - target)
        in_place = tolerance(to_target, 0.05, init)
        caged = pushing_caging(view, episode, obj, 0.007, 0.003, 0.01)
        reward = hamacher_product(caged, in_place)
        touching = (jnp.linalg.norm(obj - view.tcp_center) < 0.01) & (obs[3] > 0) & (obs[3] < 0.55)
        touching = touching & (init - to_target > 0.01)
        reward = jnp.where(touching, reward + 1.0 + 5.0 * in_place, reward)
        return jnp.where(to_target < 0.05, 10.0, reward)


TASKS = (PushBack(),)
