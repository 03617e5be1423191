"""pick-place-wall-v3: carry the puck over the wall to the goal (MetaWorld 3.1.1).

Draws (puck xyz, goal xyz), redrawn while their xy are closer than 0.15 m; the puck's free
joint goes to the drawn position (velocities zeroed). Observed object: the ``objGeom`` geom's
position and orientation as scipy's quaternion (x-y-z-w). Success: the observed puck within
0.07 of the goal.
"""

from __future__ import annotations

import jax

from openral_mjx.scenes.metaworld_mjx.task import FreeObjectTask, View, matrix_quat


class PickPlaceWall(FreeObjectTask):
    name = "pick-place-wall-v3"
    xml = "sawyer_xyz/sawyer_pick_place_wall_v3.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.05, 0.6, 0.015, -0.05, 0.85, 0.05)
    reset_high = (0.05, 0.65, 0.015, 0.05, 0.9, 0.3)
    goal_low = (-0.05, 0.85, 0.05)
    goal_high = (0.05, 0.9, 0.3)
    geoms = ("objGeom",)
    success_radius = 0.07

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.geom_pos("objGeom"), matrix_quat(view.geom_quat("objGeom"))


TASKS = (PickPlaceWall(),)
