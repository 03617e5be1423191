"""plate-slide-back-v3, plate-slide-back-side-v3: slide the plate back out (MetaWorld 3.1.1).

Both draw (plate xyz, goal xyz) from a box that is a single point for the plate; MetaWorld's
`_set_obj_xyz` writes the plate's two slides (qpos 9, 10; velocities left as they are) to
(0, 0.15) for plate-slide-back (plate inside the cabinet at y 0.75) and (-0.15, 0) for
plate-slide-back-side (inside the side cabinet). plate-slide-back writes the goal into
``data.body("puck_goal").xpos`` only (overwritten by the next kinematics: the body stays);
plate-slide-back-side moves the ``puck_goal`` body (the cabinet) to the drawn plate position.
Goal: the drawn one. Observed object: the ``puck`` geom's position and orientation as scipy's
quaternion (x-y-z-w). Success: the observed plate within 0.07 of the goal.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import ModelFacts
from openral_mjx.benchmarks.metaworld.mirror.tasks.plate_slide import SLIDES_QPOS, _PlateSlide


class _PlateSlideBack(_PlateSlide):
    slides: ClassVar[tuple[float, float]]

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[SLIDES_QPOS : SLIDES_QPOS + 2].set(jnp.asarray(self.slides))
        return qpos, qvel, {b: vec[:3] for b in self.moved_bodies}


class PlateSlideBack(_PlateSlideBack):
    name = "plate-slide-back-v3"
    reset_low = (0.0, 0.85, 0.0, -0.1, 0.6, 0.015)
    reset_high = (0.0, 0.85, 0.0, 0.1, 0.6, 0.015)
    goal_low = (-0.1, 0.6, 0.015)
    goal_high = (0.1, 0.6, 0.015)
    slides = (0.0, 0.15)


class PlateSlideBackSide(_PlateSlideBack):
    name = "plate-slide-back-side-v3"
    xml = "sawyer_xyz/sawyer_plate_slide_sideway.xml"
    reset_low = (-0.25, 0.6, 0.0, -0.05, 0.6, 0.015)
    reset_high = (-0.25, 0.6, 0.0, 0.15, 0.6, 0.015)
    goal_low = (-0.05, 0.6, 0.015)
    goal_high = (0.15, 0.6, 0.015)
    moved_bodies = ("puck_goal",)
    slides = (-0.15, 0.0)


TASKS = (PlateSlideBack(), PlateSlideBackSide())
