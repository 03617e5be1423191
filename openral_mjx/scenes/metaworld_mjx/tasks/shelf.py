"""shelf-place-v3: put the block on the shelf (MetaWorld 3.1.1).

Draws (block xyz, goal xyz), redrawn while their xy are closer than 0.1. The ``shelf`` body goes
to the goal lowered by 0.3; the goal is the ``goal`` site's model position (in the shelf's
frame) plus the shelf's, i.e. the drawn goal. The block's free joint goes to the drawn xy at
the ``obj`` body's rest height (velocities zeroed). Observed object: the ``obj`` body's position
and the ``objGeom`` geom's orientation as scipy's quaternion. Success: the observed block within
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

SHELF_DROP = (0.0, 0.0, 0.3)


class ShelfPlace(MirrorTask):
    name = "shelf-place-v3"
    xml = "sawyer_xyz/sawyer_shelf_placing.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.5, 0.019, -0.1, 0.8, 0.299)
    reset_high = (0.1, 0.6, 0.021, 0.1, 0.9, 0.301)
    goal_low = (-0.1, 0.8, 0.299)
    goal_high = (0.1, 0.9, 0.301)
    bodies = ("obj",)
    geoms = ("objGeom",)
    moved_bodies = ("shelf",)

    def accept(self, vec: jax.Array) -> jax.Array:
        return jnp.linalg.norm(vec[:2] - vec[3:5]) >= 0.1

    def _obj_init(self, facts: ModelFacts, vec: jax.Array) -> jax.Array:
        return jnp.concatenate([vec[:2], jnp.asarray(facts.rest["body:obj"][2:3], vec.dtype)])

    def _shelf(self, vec: jax.Array) -> jax.Array:
        return vec[3:6] - jnp.asarray(SHELF_DROP, vec.dtype)

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos, qvel = set_obj_xyz(facts, qpos, qvel, self._obj_init(facts, vec))
        return qpos, qvel, {"shelf": self._shelf(vec)}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        goal_local = jnp.asarray(facts.site_pos["goal"], vec.dtype)
        return {
            "target_pos": goal_local + self._shelf(vec),
            "obj_init_pos": self._obj_init(facts, vec),
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("obj"), matrix_quat(view.geom_quat("objGeom"))

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= 0.07


TASKS = (ShelfPlace(),)
