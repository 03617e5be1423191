"""hammer-v3: drive the nail with the hammer (MetaWorld 3.1.1).

The hammer's free joint (the model's unnamed joint at qpos 9) goes to the drawn position, its
velocities zeroed (its orientation stays as the hand reset leaves it); the nail box is not
moved (MetaWorld writes its default position back). Goal: the ``goal`` site. Observed objects:
the ``hammer`` and ``nail_link`` bodies, positions and ``xquat`` (w-x-y-z). Success: the
nail's slide ``NailSlideJoint`` beyond 0.09.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    MirrorTask,
    ModelFacts,
    View,
    gripper_caging,
    tolerance,
)

HAMMER_QPOS, HAMMER_DOF = 9, 9  # MetaWorld's `_set_hammer_xyz`: qpos[9:12], qvel[9:15]
HANDLE_HALF_LENGTH = 0.07  # half MetaWorld's `HAMMER_HANDLE_LENGTH`
HEAD_OFFSET = (0.16, 0.06, 0.0)  # the hammer's head, from its body


class Hammer(MirrorTask):
    name = "hammer-v3"
    xml = "sawyer_xyz/sawyer_hammer.xml"
    hand_init_pos = (0.0, 0.4, 0.2)
    reset_low = (-0.1, 0.4, 0.0)
    reset_high = (0.1, 0.5, 0.0)
    goal_low = (0.2399, 0.7399, 0.109)
    goal_high = (0.2401, 0.7401, 0.111)
    bodies = ("hammer", "nail_link", "leftpad", "rightpad")
    sites = ("goal",)
    has_reward = True

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[HAMMER_QPOS : HAMMER_QPOS + 3].set(vec)
        qvel = qvel.at[HAMMER_DOF : HAMMER_DOF + 6].set(0.0)
        return qpos, qvel, {}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {"target_pos": view.site_pos("goal"), "obj_init_pos": vec}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        pos = jnp.concatenate([view.body_pos("hammer"), view.body_pos("nail_link")])
        quat = jnp.concatenate([view.body_quat("hammer"), view.body_quat("nail_link")])
        return pos, quat

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return view.qpos("NailSlideJoint") > 0.09

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: (2 x the handle caged, its x snapped to the hand's within half the
        handle's length; 6 x the head lifted (0.1) and at the nail (0.9)) x the hammer lying
        flat; 10 on success where that reward is above 5."""
        hand, hammer = obs[:3], obs[4:7]
        head = hammer + jnp.asarray(HEAD_OFFSET, jnp.float32)
        near = jnp.abs(hammer[0] - hand[0]) < HANDLE_HALF_LENGTH
        handle = hammer.at[0].set(jnp.where(near, hand[0], hammer[0]))
        flat = jnp.maximum(
            1.0 - jnp.linalg.norm(obs[7:11] - jnp.asarray([1.0, 0.0, 0.0, 0.0])) / 0.4, 0.0
        )
        grab = gripper_caging(view, episode, action, handle, 0.015, 0.02, 0.01)
        to_nail = jnp.linalg.norm(episode["target_pos"] - head)
        in_place = 0.1 * (head[2] > 0.02) + 0.9 * tolerance(to_nail, 0.02, 0.2)
        reward = (2.0 * grab + 6.0 * in_place) * flat
        return jnp.where(self.success(obs, view, episode) & (reward > 5.0), 10.0, reward)


TASKS = (Hammer(),)
