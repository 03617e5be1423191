"""pick-place-wall-v3: carry the puck over the wall to the goal (MetaWorld 3.1.1).

Draws (puck xyz, goal xyz), redrawn while their xy are closer than 0.15 m; the puck's free
joint goes to the drawn position (velocities zeroed). Observed object: the ``objGeom`` geom's
position and orientation as scipy's quaternion (x-y-z-w). Success: the observed puck within
0.07 of the goal.
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


class PickPlaceWall(MirrorTask):
    name = "pick-place-wall-v3"
    xml = "sawyer_xyz/sawyer_pick_place_wall_v3.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.05, 0.6, 0.015, -0.05, 0.85, 0.05)
    reset_high = (0.05, 0.65, 0.015, 0.05, 0.9, 0.3)
    goal_low = (-0.05, 0.85, 0.05)
    goal_high = (0.05, 0.9, 0.3)
    geoms = ("objGeom",)

    def accept(self, vec: jax.Array) -> jax.Array:
        return jnp.linalg.norm(vec[:2] - vec[3:5]) >= 0.15

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos, qvel = set_obj_xyz(facts, qpos, qvel, vec[:3])
        return qpos, qvel, {}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {"target_pos": vec[3:6], "obj_init_pos": vec[:3]}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.geom_pos("objGeom"), matrix_quat(view.geom_quat("objGeom"))

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= 0.07


TASKS = (PickPlaceWall(),)
