"""pick-out-of-hole-v3: lift the peg out of the hole to the goal (MetaWorld 3.1.1).

Draws (peg xyz, goal xyz), redrawn while their xy are closer than 0.15 m (never, with its
box); the peg's free joint goes to the drawn position (velocities zeroed). Observed object: the
``obj`` body's position and ``xquat`` (w-x-y-z). Success: the observed peg within 0.07 of the
goal.
"""

from __future__ import annotations

import jax

from openral_mjx.scenes.metaworld_mjx.task import FreeObjectTask, View


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
    bodies = ("obj",)
    success_radius = 0.07

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("obj"), view.body_quat("obj")


TASKS = (PickOutOfHole(),)
