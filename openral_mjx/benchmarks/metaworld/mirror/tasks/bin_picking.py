"""bin-picking-v3: move the cube from one bin to the other (MetaWorld 3.1.1).

The vector's first two entries are the cube's xy (the rest, a goal box around the target
bin's centre, is unused); the cube's free joint (qpos 9..11) goes there at its height after
the hand reset, velocities zeroed. The goal is the fixed ``bin_goal`` body's position.
Observed object: the ``obj`` body and its ``xquat`` (w-x-y-z). Success: the observed cube
within 0.05 m of the goal.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import MirrorTask, ModelFacts, View

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
    bodies = ("obj", "bin_goal")

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


TASKS = (BinPicking(),)
