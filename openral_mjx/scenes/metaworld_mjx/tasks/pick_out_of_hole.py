"""pick-out-of-hole-v3: lift the peg out of the hole to the goal (MetaWorld 3.1.1).

Draws (peg xyz, goal xyz), redrawn while their xy are closer than 0.15 m (never, with its
box); the peg's free joint goes to the drawn position (velocities zeroed). Observed object: the
``obj`` body's position and ``xquat`` (w-x-y-z). Success: the observed peg within 0.07 of the
goal.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.scenes.metaworld_mjx.task import MirrorTask, ModelFacts, View, set_obj_xyz


class PickOutOfHole(MirrorTask):
    name = "pick-out-of-hole-v3"
    xml = "sawyer_xyz/sawyer_pick_out_of_hole.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (0.0, 0.75, 0.02, -0.1, 0.5, 0.15)
    reset_high = (0.0, 0.75, 0.02, 0.1, 0.6, 0.3)
    goal_low = (-0.1, 0.5, 0.15)
    goal_high = (0.1, 0.6, 0.3)
    hand_low = (-0.5, 0.40, -0.05)
    hand_high = (0.5, 1.0, 0.5)
    bodies = ("obj",)

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
        return view.body_pos("obj"), view.body_quat("obj")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= 0.07


TASKS = (PickOutOfHole(),)
