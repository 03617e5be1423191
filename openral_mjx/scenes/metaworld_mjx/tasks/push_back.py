"""push-back-v3: push the puck back towards the robot (MetaWorld 3.1.1).

Draws (puck xyz, goal xyz); the goal is the drawn xy at the ``objGeom`` geom's rest height
(`adjust_initObjPos`), redrawn while the puck's and the goal's xy are closer than 0.15. The
puck's free joint goes to the drawn xy at that height (velocities zeroed). Observed object: the
geom's position and orientation as scipy's quaternion (x-y-z-w). Success: the observed puck
within 0.07 of the goal.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.scenes.metaworld_mjx.task import (
    MirrorTask,
    ModelFacts,
    View,
    matrix_quat,
    set_obj_xyz,
)


class PushBack(MirrorTask):
    name = "push-back-v3"
    xml = "sawyer_xyz/sawyer_push_back_v3.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.8, 0.02, -0.1, 0.6, 0.0199)
    reset_high = (0.1, 0.85, 0.02, 0.1, 0.7, 0.0201)
    goal_low = (-0.1, 0.6, 0.0199)
    goal_high = (0.1, 0.7, 0.0201)
    geoms = ("objGeom",)

    def accept(self, vec: jax.Array) -> jax.Array:
        return jnp.linalg.norm(vec[:2] - vec[3:5]) >= 0.15

    def _at_rest_height(self, facts: ModelFacts, xy: jax.Array) -> jax.Array:
        return jnp.concatenate([xy, jnp.asarray(facts.rest["geom:objGeom"][2:3], xy.dtype)])

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos, qvel = set_obj_xyz(facts, qpos, qvel, self._at_rest_height(facts, vec[:2]))
        return qpos, qvel, {}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {
            "target_pos": self._at_rest_height(facts, vec[3:5]),
            "obj_init_pos": self._at_rest_height(facts, vec[:2]),
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.geom_pos("objGeom"), matrix_quat(view.geom_quat("objGeom"))

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= 0.07


TASKS = (PushBack(),)
