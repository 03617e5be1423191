"""plate-slide-v3, plate-slide-side-v3: slide the plate into the goal (MetaWorld 3.1.1).

Draws (plate xyz, goal xyz); the plate's two slides (qpos 9, 10) go to 0 (velocities left as
they are), the goal is the drawn one. plate-slide moves the ``puck_goal`` body there;
plate-slide-side writes the drawn goal into ``data.body("puck_goal").xpos`` only, which the
next kinematics overwrite, so its goal body stays at the model's default. Observed object: the
``puck`` geom's position and orientation as scipy's quaternion (x-y-z-w). Success: the
observed plate within 0.07 of the goal.

Rewards (MetaWorld's v2): the tcp at the plate and the plate at the goal (long tails, within
0.05, margins from the drawn plate position); plate-slide weighs their Hamacher product by 8,
the other three (`side_reward`) give 1.5 for the reach and 2 + 7 x in-place once the tcp is low
and near; 10 within 0.05 of the goal.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    DrawnGoalTask,
    ModelFacts,
    View,
    hamacher_product,
    matrix_quat,
    tolerance,
)

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

    has_reward = True
    side_reward: ClassVar[bool] = True  # all but plate-slide-v3

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        obj, target, start = obs[4:7], episode["target_pos"], episode["obj_init_pos"]
        shrink = 0.05 if self.side_reward else 0.0  # the others' margins lose the radius
        to_target = jnp.linalg.norm(obj - target)
        in_place = tolerance(to_target, 0.05, jnp.linalg.norm(start - target) - shrink)
        tcp = view.tcp_center
        tcp_to_obj = jnp.linalg.norm(tcp - obj)
        reach = tolerance(tcp_to_obj, 0.05, jnp.linalg.norm(episode["init_tcp"] - start) - shrink)
        if self.side_reward:
            low_near = (tcp[2] <= 0.03) & (tcp_to_obj < 0.07)
            reward = jnp.where(low_near, 2.0 + 7.0 * in_place, 1.5 * reach)
        else:
            reward = 8.0 * hamacher_product(reach, in_place)
        return jnp.where(to_target < 0.05, 10.0, reward)


class PlateSlide(_PlateSlide):
    name = "plate-slide-v3"
    reset_low = (0.0, 0.6, 0.0, -0.1, 0.85, 0.0)
    reset_high = (0.0, 0.6, 0.0, 0.1, 0.9, 0.0)
    goal_low = (-0.1, 0.85, 0.0)
    goal_high = (0.1, 0.9, 0.0)
    moved_bodies = ("puck_goal",)
    side_reward = False


class PlateSlideSide(_PlateSlide):
    name = "plate-slide-side-v3"
    xml = "sawyer_xyz/sawyer_plate_slide_sideway.xml"
    reset_low = (0.0, 0.6, 0.0, -0.3, 0.54, 0.0)
    reset_high = (0.0, 0.6, 0.0, -0.25, 0.66, 0.0)
    goal_low = (-0.3, 0.54, 0.0)
    goal_high = (-0.25, 0.66, 0.0)


TASKS = (PlateSlide(), PlateSlideSide())
