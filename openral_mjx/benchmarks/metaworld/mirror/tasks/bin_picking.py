"""bin-picking-v3: move the cube from one bin to the other (MetaWorld 3.1.1).

The vector's first two entries are the cube's xy (the rest, a goal box around the target
bin's centre, is unused); the cube's free joint (qpos 9..11) goes there at its height after
the hand reset, velocities zeroed. The goal is the fixed ``bin_goal`` body's position.
Observed object: the ``obj`` body and its ``xquat`` (w-x-y-z). Success: the observed cube
within 0.05 m of the goal. Reward: MetaWorld's v2, whose in-place margin is the cube's
distance to the goal at the episode's first step; the mirror takes it at the reset (the cube
rests there, so the two differ by how far the first step moves it: not at all on 4 of 5 seeds
under MetaWorld's expert, 7.7 mm on the fifth, where the rewards then differ by up to 5.9e-3).
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
    hamacher_product,
    tolerance,
)

OBJ_QPOS = 9  # MetaWorld's `_set_obj_xyz`: qpos[9:12] = pos, qvel[9:15] = 0


class BinPicking(MirrorTask):
    name = "bin-picking-v3"
    xml = "sawyer_xyz/sawyer_bin_picking.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    hand_low = (-0.5, 0.40, 0.07)
    hand_high = (0.5, 1.0, 0.5)
    reset_low = (-0.21, 0.65, 0.02, 0.1199, 0.699, -0.001)
    reset_high = (-0.03, 0.75, 0.02, 0.1201, 0.701, 0.001)
    goal_low = (0.1199, 0.699, -0.001)
    goal_high = (0.1201, 0.701, 0.001)
    bodies = ("obj", "bin_goal", "leftpad", "rightpad")
    has_reward = True

    def _obj_init(self, facts: ModelFacts, vec: jax.Array) -> jax.Array:
        return jnp.concatenate([vec[:2], jnp.asarray(facts.rest["body:obj"][2:3])])

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[OBJ_QPOS : OBJ_QPOS + 3].set(self._obj_init(facts, vec))
        qvel = qvel.at[OBJ_QPOS : OBJ_QPOS + 6].set(0.0)
        return qpos, qvel, {}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {"target_pos": view.body_pos("bin_goal"), "obj_init_pos": self._obj_init(facts, vec)}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("obj"), view.body_quat("obj")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= 0.05

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: the cube caged and gripped times its approach to the goal, plus 1
        and 5x (that approach while the hand stays above two funnels, round the cube's start
        and the goal) once lifted in an unpinched grip; 10 within 0.05."""
        hand, obj = obs[:3], obs[4:7]
        target, start = episode["target_pos"], episode["obj_init_pos"]
        to_target = jnp.linalg.norm(obj - target)
        in_place = tolerance(to_target, 0.05, jnp.linalg.norm(start - target))
        radii = jnp.stack(
            [jnp.linalg.norm(hand[:2] - start[:2]), jnp.linalg.norm(hand[:2] - target[:2])]
        )
        funnels = jnp.where(
            radii > 0.03, 0.02 * jnp.log(jnp.maximum(radii - 0.03, 1e-30)) + 0.2, 0.0
        )
        floor = jnp.min(funnels)
        above = jnp.where(
            hand[2] >= floor, 1.0, tolerance(jnp.maximum(floor - hand[2], 0.0), 0.01, 0.05)
        )
        grasped = gripper_caging(view, episode, action, obj, 0.015, 0.05, 0.01, effort=0.7)
        reward = hamacher_product(grasped, in_place)
        held = (jnp.linalg.norm(obj - hand) < 0.04) & (obs[3] >= 0.43) & (obj[2] - 0.02 > start[2])
        reward = jnp.where(held, reward + 1.0 + 5.0 * hamacher_product(above, in_place), reward)
        return jnp.where(to_target < 0.05, 10.0, reward)


TASKS = (BinPicking(),)
