"""push-back-v3: push the puck back towards the robot (MetaWorld 3.1.1).

Draws (puck xyz, goal xyz); the goal is the drawn xy at the ``objGeom`` geom's rest height
(`adjust_initObjPos`), redrawn while the puck's and the goal's xy are closer than 0.15. The
puck's free joint goes to the drawn xy at that height (velocities zeroed). Observed object: the
geom's position and orientation as scipy's quaternion (x-y-z-w). Success: the observed puck
within 0.07 of the goal.
"""

from __future__ import annotations

import jax

from openral_mjx.benchmarks.metaworld.mirror.task import (
    FreeObjectTask,
    ModelFacts,
    View,
    at_rest_height,
    matrix_quat,
)


class PushBack(FreeObjectTask):
    name = "push-back-v3"
    xml = "sawyer_xyz/sawyer_push_back_v3.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.8, 0.02, -0.1, 0.6, 0.0199)
    reset_high = (0.1, 0.85, 0.02, 0.1, 0.7, 0.0201)
    goal_low = (-0.1, 0.6, 0.0199)
    goal_high = (0.1, 0.7, 0.0201)
    geoms = ("objGeom",)
    success_radius = 0.07

    def obj_init(self, facts: ModelFacts, vec: jax.Array) -> jax.Array:
        return at_rest_height(facts, vec[:2], "geom:objGeom", vec.dtype)

    def target(self, facts: ModelFacts, vec: jax.Array, view: View) -> jax.Array:
        return at_rest_height(facts, vec[3:5], "geom:objGeom", vec.dtype)

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.geom_pos("objGeom"), matrix_quat(view.geom_quat("objGeom"))


TASKS = (PushBack(),)
