"""soccer-v3: kick the ball into the goal (MetaWorld 3.1.1).

Draws (ball xyz, goal xyz), redrawn while their xy are closer than 0.15; the ball's free joint
goes to the drawn xy at z 0.03 (velocities zeroed), the ``goal_whole`` body (the net) to the
drawn goal, which is the target. Observed object: the ``soccer_ball`` body's position and its
orientation as scipy's quaternion (x-y-z-w). Success: the observed ball within 0.07 of the
goal (the reward weights x by 3; the success test does not).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    FreeObjectTask,
    ModelFacts,
    View,
    matrix_quat,
)

FREE_QPOS, FREE_DOF = 9, 9  # MetaWorld's `_set_obj_xyz` writes qpos[9:12], qvel[9:15]
BALL_Z = 0.03  # init_config["obj_init_pos"][-1]


class Soccer(FreeObjectTask):
    name = "soccer-v3"
    xml = "sawyer_xyz/sawyer_soccer.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.6, 0.03, -0.1, 0.8, 0.0)
    reset_high = (0.1, 0.7, 0.03, 0.1, 0.9, 0.0)
    goal_low = (-0.1, 0.8, 0.0)
    goal_high = (0.1, 0.9, 0.0)
    bodies = ("soccer_ball",)
    moved_bodies = ("goal_whole",)
    # `compute_reward` scales x by 3 for its reward but returns the plain distance
    success_radius = 0.07

    def obj_init(self, facts: ModelFacts, vec: jax.Array) -> jax.Array:
        return jnp.concatenate([vec[:2], jnp.full((1,), BALL_Z, vec.dtype)])

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[FREE_QPOS : FREE_QPOS + 3].set(self.obj_init(facts, vec))
        qvel = qvel.at[FREE_DOF : FREE_DOF + 6].set(0.0)
        return qpos, qvel, {"goal_whole": vec[3:6]}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("soccer_ball"), matrix_quat(view.body_quat("soccer_ball"))


TASKS = (Soccer(),)
