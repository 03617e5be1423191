"""assembly-v3, disassemble-v3: the round nut (wrench) and its peg (MetaWorld 3.1.1).

Both draw (nut xyz, goal xyz) and redraw while their xy are closer than 0.1 m; the nut's free
joint (qpos 9..11, MetaWorld's ``_set_obj_xyz``) gets the drawn position with its velocities
zeroed, and the ``peg`` body is moved. Observed object: the ``RoundNut-8`` site (the handle's
end) and the ``RoundNut`` body's ``xquat`` (w-x-y-z).

- assembly: the peg goes 0.05 m under the drawn goal; success once the nut's centre (the
  ``RoundNut`` site) lies within 0.02 m of the goal in xy and below it.
- disassemble: the peg goes 0.03 m above the nut's drawn position and the goal 0.15 m above
  it; success once the observed nut's height exceeds the goal's. MetaWorld's hand reset runs
  with the peg already moved (its reset runs twice), and where the peg meets the nut's
  default pose it turns the nut; the mirror's shared hand-reset state cannot show that.
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

OBJ_QPOS = 9  # MetaWorld's `_set_obj_xyz`: qpos[9:12] = pos, qvel[9:15] = 0
OBJ_QVEL = 9
WRENCH_HALF_LENGTH = 0.01  # half MetaWorld's `WRENCH_HANDLE_LENGTH`


def _set_nut(qpos: jax.Array, qvel: jax.Array, pos: jax.Array) -> tuple[jax.Array, jax.Array]:
    return qpos.at[OBJ_QPOS : OBJ_QPOS + 3].set(pos), qvel.at[OBJ_QVEL : OBJ_QVEL + 6].set(0.0)


def _laid_down(obs: jax.Array) -> jax.Array:
    """MetaWorld's ``_reward_quat``: 1 - |observed quaternion - (0.707, 0, 0, 0.707)| / 0.4,
    floored at 0."""
    ideal = jnp.asarray([0.707, 0.0, 0.0, 0.707], jnp.float32)
    return jnp.maximum(1.0 - jnp.linalg.norm(obs[7:11] - ideal) / 0.4, 0.0)


class _Nut(MirrorTask):
    xml = "sawyer_xyz/sawyer_assembly_peg.xml"
    bodies = ("RoundNut", "leftpad", "rightpad")
    sites = ("RoundNut", "RoundNut-8")
    moved_bodies = ("peg",)
    has_reward = True
    density: str

    def _grab(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """The caging reward on the handle's end, its x snapped to the hand's within half the
        handle's length (MetaWorld treats the handle as a sphere there)."""
        hand, wrench = obs[:3], obs[4:7]
        near = jnp.abs(wrench[0] - hand[0]) < WRENCH_HALF_LENGTH
        wrench = wrench.at[0].set(jnp.where(near, hand[0], wrench[0]))
        return gripper_caging(
            view, episode, action, wrench, 0.015, 0.02, 0.01, density=self.density
        )

    def accept(self, vec: jax.Array) -> jax.Array:
        return jnp.linalg.norm(vec[:2] - vec[3:5]) >= 0.1

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos("RoundNut-8"), view.body_quat("RoundNut")


class Assembly(_Nut):
    name = "assembly-v3"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (0.0, 0.6, 0.02, -0.1, 0.75, 0.1)
    reset_high = (0.0, 0.6, 0.02, 0.1, 0.85, 0.1)
    goal_low = (-0.1, 0.75, 0.1)
    goal_high = (0.1, 0.85, 0.1)
    density = "medium"

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos, qvel = _set_nut(qpos, qvel, vec[:3])
        return qpos, qvel, {"peg": vec[3:6] - jnp.array([0.0, 0.0, 0.05])}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {"target_pos": vec[3:6], "obj_init_pos": vec[:3]}

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        error = episode["target_pos"] - view.site_pos("RoundNut")
        return (jnp.linalg.norm(error[:2]) < 0.02) & (error[2] > 0.0)

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: (2 x the handle caged, 6 x the nut lifted (0.1) and brought down a
        funnel over the peg (0.9, z weighted 3)) x the nut lying flat; 10 on success."""
        centre = view.site_pos("RoundNut")
        error = episode["target_pos"] - centre
        radius = jnp.linalg.norm(error[:2])
        success = (radius < 0.02) & (error[2] > 0.0)
        threshold = jnp.where(success, 0.02, 0.01)  # wider once on the peg
        height = jnp.where(
            radius > threshold,
            0.02 * jnp.log(jnp.maximum(radius - threshold, 1e-30)) + 0.2,
            0.0,
        )
        error = error.at[2].set(height - centre[2])
        scale = jnp.asarray([1.0, 1.0, 3.0], jnp.float32)
        lifted = (centre[2] > 0.02) | (radius < threshold)
        in_place = 0.1 * lifted + 0.9 * tolerance(jnp.linalg.norm(error * scale), 0.02, 0.4)
        grab = self._grab(obs, view, episode, action)
        reward = (2.0 * grab + 6.0 * in_place) * _laid_down(obs)
        return jnp.where(success, 10.0, reward)


class Disassemble(_Nut):
    name = "disassemble-v3"
    hand_reset_per_episode = True  # the moved peg knocks the nut during it
    hand_init_pos = (0.0, 0.4, 0.2)
    reset_low = (0.0, 0.6, 0.025, -0.1, 0.6, 0.1699)
    reset_high = (0.1, 0.75, 0.02501, 0.1, 0.75, 0.1701)
    goal_low = (-0.1, 0.6, 0.1749)
    goal_high = (0.1, 0.75, 0.1751)
    density = "high"

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos, qvel = _set_nut(qpos, qvel, vec[:3])
        return qpos, qvel, {"peg": vec[:3] + jnp.array([0.0, 0.0, 0.03])}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {"target_pos": vec[:3] + jnp.array([0.0, 0.0, 0.15]), "obj_init_pos": vec[:3]}

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return obs[6] > episode["target_pos"][2]

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: (2 x the handle caged, 6 x the nut lifted (0.1) and brought to
        0.1 over the goal (0.9)) x the nut lying flat; 10 on success."""
        centre = view.site_pos("RoundNut")
        error = episode["target_pos"] + jnp.asarray([0.0, 0.0, 0.1], jnp.float32) - centre
        in_place = 0.1 * (centre[2] > 0.02) + 0.9 * tolerance(jnp.linalg.norm(error), 0.02, 0.2)
        grab = self._grab(obs, view, episode, action)
        reward = (2.0 * grab + 6.0 * in_place) * _laid_down(obs)
        return jnp.where(self.success(obs, view, episode), 10.0, reward)


TASKS = (Assembly(), Disassemble())
