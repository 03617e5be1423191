"""basketball-v3: dunk the ball through the hoop (MetaWorld 3.1.1).

The vector is (ball xyz, hoop xyz), redrawn while their xy are closer than 0.15 m. The ball's
free joint (qpos 9..11) goes to the drawn xy at height 0.03 (MetaWorld's initial height, a
float32), its velocities zeroed; the ``basket_goal`` body goes to the drawn hoop position. The
goal is the hoop's ``goal`` site after placement (hoop + (0, -0.083, 0.25)). Observed object:
the ``bsktball`` body and its ``xquat`` (w-x-y-z). Success: the observed ball within 0.08 of
the goal raised to z = 0.3, with the z error counted twice.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.benchmarks.metaworld.mirror.task import (
    FreeObjectTask,
    ModelFacts,
    View,
    gripper_caging,
    hamacher_product,
    tolerance,
)

BALL_QPOS = 9  # MetaWorld's `_set_obj_xyz`: qpos[9:12] = pos, qvel[9:15] = 0
BALL_Z = float(np.float32(0.03))  # init_config["obj_init_pos"][-1] (a float32 array)
TARGET_RADIUS = 0.08


class Basketball(FreeObjectTask):
    name = "basketball-v3"
    xml = "sawyer_xyz/sawyer_basketball.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.6, 0.0299, -0.1, 0.85, 0.0)
    reset_high = (0.1, 0.7, 0.0301, 0.1, 0.9 + 1e-7, 0.0)
    goal_low = (-0.1, 0.85 - 0.083, 0.2499)
    goal_high = (0.1, 0.9 + 1e-7 - 0.083, 0.2501)
    bodies = ("bsktball", "leftpad", "rightpad")
    sites = ("goal",)
    moved_bodies = ("basket_goal",)
    has_reward = True

    def obj_init(self, facts: ModelFacts, vec: jax.Array) -> jax.Array:
        return jnp.concatenate([vec[:2], jnp.array([BALL_Z])])

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[BALL_QPOS : BALL_QPOS + 3].set(self.obj_init(facts, vec))
        qvel = qvel.at[BALL_QPOS : BALL_QPOS + 6].set(0.0)
        return qpos, qvel, {"basket_goal": vec[3:6]}

    def target(self, facts: ModelFacts, vec: jax.Array, view: View) -> jax.Array:
        return view.site_pos("goal")

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("bsktball"), view.body_quat("bsktball")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        target = episode["target_pos"].at[2].set(0.3)
        error = (obs[4:7] - target) * jnp.array([1.0, 1.0, 2.0])
        return jnp.linalg.norm(error) <= TARGET_RADIUS

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: the ball caged (or held lifted) times its approach to the hoop at
        0.3 m (z weighted 2x), plus 1 + 5 x the approach while held lifted; 10 on success."""
        obj, start = obs[4:7], episode["obj_init_pos"]
        target = episode["target_pos"].at[2].set(0.3)
        scale = jnp.asarray([1.0, 1.0, 2.0], jnp.float32)
        to_target = jnp.linalg.norm((obj - target) * scale)
        in_place = tolerance(to_target, TARGET_RADIUS, jnp.linalg.norm((start - target) * scale))
        near = jnp.linalg.norm(obj - view.tcp_center) < 0.035
        held = near & (obs[3] > 0) & (obj[2] - 0.01 > start[2])
        caged = gripper_caging(view, episode, action, obj, 0.025, 0.06, 0.005)
        reward = hamacher_product(jnp.where(held, 1.0, caged), in_place)
        reward = jnp.where(held, reward + 1.0 + 5.0 * in_place, reward)
        return jnp.where(to_target < TARGET_RADIUS, 10.0, reward)


TASKS = (Basketball(),)
