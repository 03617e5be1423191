"""shelf-place-v3: put the block on the shelf (MetaWorld 3.1.1).

Draws (block xyz, goal xyz), redrawn while their xy are closer than 0.1. The ``shelf`` body goes
to the goal lowered by 0.3; the goal is the ``goal`` site's model position (in the shelf's
frame) plus the shelf's, i.e. the drawn goal. The block's free joint goes to the drawn xy at
the ``obj`` body's rest height (velocities zeroed). Observed object: the ``obj`` body's position
and the ``objGeom`` geom's orientation as scipy's quaternion. Success: the observed block within
0.07 of the goal.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from openral_mjx.scenes.metaworld_mjx.task import (
    FreeObjectTask,
    ModelFacts,
    View,
    at_rest_height,
    matrix_quat,
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
    bodies = ("obj",)
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


TASKS = (ShelfPlace(),)
