"""peg-insert-side-v3, peg-unplug-side-v3: the peg and its box, side-on (MetaWorld 3.1.1).

peg-insert-side draws (peg xyz, box xyz), redrawn while their xy are closer than 0.1: the peg's
free joint goes to the drawn position (orientation and angular state kept, velocities zeroed),
the ``box`` body to the drawn box position; goal: box + (0.03, 0, 0.13). Observed object: the
``pegGrasp`` site and the peg's orientation (the site's frame is the body's) as scipy's
quaternion; success: the ``pegHead`` site within 0.07 of the goal, with y and z weighted 2.

peg-unplug-side draws the box position: the ``box`` body goes there, the plug's free joint to
box + (0.044, 0, 0.131) with identity orientation and zero linear velocity; MetaWorld leaves
the angular velocity as its last hand reset left it, which knocks the plug about inside the
moved box, so the mirror simulates that hand reset per episode; goal: plug + (0.15, 0, 0).
Observed object: the ``pegEnd`` site and the ``plug1`` body's quaternion as MuJoCo's
(w-x-y-z); success: within 0.07 of goal.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.scenes.metaworld_mjx.task import MirrorTask, ModelFacts, View, matrix_quat

FREE_QPOS, FREE_DOF = 9, 9  # MetaWorld's `_set_obj_xyz` writes qpos[9:12], qvel[9:15]
INSERT_GOAL_OFFSET = (0.03, 0.0, 0.13)
PLUG_OFFSET = (0.044, 0.0, 0.131)
UNPLUG_GOAL_OFFSET = (0.15, 0.0, 0.0)


class PegInsertSide(MirrorTask):
    name = "peg-insert-side-v3"
    xml = "sawyer_xyz/sawyer_peg_insertion_side.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (0.0, 0.5, 0.02, -0.35, 0.4, -0.001)
    reset_high = (0.2, 0.7, 0.02, -0.25, 0.7, 0.001)
    goal_low = (-0.35 + 0.03, 0.4, -0.001 + 0.13)
    goal_high = (-0.25 + 0.03, 0.7, 0.001 + 0.13)
    bodies = ("peg",)
    sites = ("pegGrasp", "pegHead")
    moved_bodies = ("box",)

    def accept(self, vec: jax.Array) -> jax.Array:
        return jnp.linalg.norm(vec[:2] - vec[3:5]) >= 0.1

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[FREE_QPOS : FREE_QPOS + 3].set(vec[:3])
        qvel = qvel.at[FREE_DOF : FREE_DOF + 6].set(0.0)
        return qpos, qvel, {"box": vec[3:6]}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {
            "target_pos": vec[3:6] + jnp.asarray(INSERT_GOAL_OFFSET),
            "obj_init_pos": vec[:3],
            "peg_head_pos_init": view.site_pos("pegHead"),
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos("pegGrasp"), matrix_quat(view.body_quat("peg"))

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        scale = jnp.asarray((1.0, 2.0, 2.0))
        head = view.site_pos("pegHead")
        return jnp.linalg.norm((head - episode["target_pos"]) * scale) <= 0.07


class PegUnplugSide(MirrorTask):
    name = "peg-unplug-side-v3"
    xml = "sawyer_xyz/sawyer_peg_unplug_side.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.25, 0.6, -0.001)
    reset_high = (-0.15, 0.8, 0.001)
    goal_low = (-0.25 + 0.194, 0.6, -0.001 + 0.131)
    goal_high = (-0.15 + 0.194, 0.8, 0.001 + 0.131)
    bodies = ("plug1",)
    sites = ("pegEnd",)
    moved_bodies = ("box",)
    # MetaWorld's final hand reset runs with the box already moved and the plug at its model
    # default, inside the moved box: the plug is knocked about, and `_set_obj_xyz` keeps the
    # angular velocity it leaves (qvel[12:15]), so that velocity depends on the episode
    hand_reset_per_episode = True

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        plug = vec[:3] + jnp.asarray(PLUG_OFFSET)
        qpos = qpos.at[FREE_QPOS : FREE_QPOS + 3].set(plug)
        qpos = qpos.at[FREE_QPOS + 3 : FREE_QPOS + 7].set(jnp.asarray((1.0, 0.0, 0.0, 0.0)))
        qvel = qvel.at[FREE_DOF : FREE_DOF + 3].set(0.0)
        return qpos, qvel, {"box": vec[:3]}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        plug = vec[:3] + jnp.asarray(PLUG_OFFSET)
        return {
            "target_pos": plug + jnp.asarray(UNPLUG_GOAL_OFFSET),
            "obj_init_pos": view.site_pos("pegEnd"),
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos("pegEnd"), view.body_quat("plug1")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= 0.07


TASKS = (PegInsertSide(), PegUnplugSide())
