"""soccer-v3: kick the ball into the goal (MetaWorld 3.1.1).

Draws (ball xyz, goal xyz), redrawn while their xy are closer than 0.15; the ball's free joint
goes to the drawn xy at z 0.03 (velocities zeroed), the ``goal_whole`` body (the net) to the
drawn goal, which is the target. Observed object: the ``soccer_ball`` body's position and its
orientation as scipy's quaternion (x-y-z-w). Success: the observed ball within 0.07 of the
goal (the reward weights x by 3; the success test does not).
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
    matrix_quat,
    pushing_caging,
    tolerance,
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
    bodies = ("soccer_ball", "leftpad", "rightpad")
    has_reward = True
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

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: 3 x the ball caged (its own caging), 6.5 x its approach to the goal
        (x weighted 3; the margin is the ball's current distance from its start), cut back
        when the ball passes the goal line wide of the net; 10 within 0.07."""
        obj, target = obs[4:7], episode["target_pos"]
        scale = jnp.asarray([3.0, 1.0, 1.0], jnp.float32)
        to_target = jnp.linalg.norm((obj - target) * scale)
        moved = jnp.linalg.norm((obj - episode["obj_init_pos"]) * scale)
        in_place = tolerance(to_target, 0.07, moved)
        line = target[1] - 0.1
        wide = (obj[1] > line) & (jnp.abs(obj[0] - target[0]) > 0.1)
        cut = jnp.clip(in_place - 2.0 * (obj[1] - line) / (1.0 - line), 0.0, 1.0)
        in_place = jnp.where(wide, cut, in_place)
        caged = pushing_caging(view, episode, obj, 0.013, 0.01, 0.005)
        return jnp.where(to_target < 0.07, 10.0, 3.0 * caged + 6.5 * in_place)


TASKS = (Soccer(),)
