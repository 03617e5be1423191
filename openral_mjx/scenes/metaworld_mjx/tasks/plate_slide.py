"""plate-slide-v3, plate-slide-side-v3: slide the plate into the goal (MetaWorld 3.1.1).

Draws (plate xyz, goal xyz); the plate's two slides (qpos 9, 10) go to 0 (velocities left as
they are), the goal is the drawn one. plate-slide moves the ``puck_goal`` body there;
plate-slide-side writes the drawn goal into ``data.body("puck_goal").xpos`` only, which the
next kinematics overwrite, so its goal body stays at the model's default. Observed object: the
``puck`` geom's position and orientation as scipy's quaternion (x-y-z-w). Success: the
observed plate within 0.07 of the goal.
"""

from __future__ import annotations

import jax

from openral_mjx.scenes.metaworld_mjx.task import DrawnGoalTask, ModelFacts, View, matrix_quat

SLIDES_QPOS = 9  # MetaWorld's `_set_obj_xyz` writes qpos[9:11]


class _PlateSlide(DrawnGoalTask):
    xml = "sawyer_xyz/sawyer_plate_slide.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    geoms = ("puck",)
    success_radius = 0.07

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[SLIDES_QPOS : SLIDES_QPOS + 2].set(0.0)
        return qpos, qvel, {b: vec[3:6] for b in self.moved_bodies}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.geom_pos("puck"), matrix_quat(view.geom_quat("puck"))


class PlateSlide(_PlateSlide):
    name = "plate-slide-v3"
    reset_low = (0.0, 0.6, 0.0, -0.1, 0.85, 0.0)
    reset_high = (0.0, 0.6, 0.0, 0.1, 0.9, 0.0)
    goal_low = (-0.1, 0.85, 0.0)
    goal_high = (0.1, 0.9, 0.0)
    moved_bodies = ("puck_goal",)


class PlateSlideSide(_PlateSlide):
    name = "plate-slide-side-v3"
    xml = "sawyer_xyz/sawyer_plate_slide_sideway.xml"
    reset_low = (0.0, 0.6, 0.0, -0.3, 0.54, 0.0)
    reset_high = (0.0, 0.6, 0.0, -0.25, 0.66, 0.0)
    goal_low = (-0.3, 0.54, 0.0)
    goal_high = (-0.25, 0.66, 0.0)


TASKS = (PlateSlide(), PlateSlideSide())
