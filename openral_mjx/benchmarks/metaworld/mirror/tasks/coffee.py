"""coffee-button-v3, coffee-pull-v3, coffee-push-v3: the mug and the coffee machine
(MetaWorld 3.1.1, ``sawyer_coffee.xml``).

The mug's free joint comes first in this model (qpos 0..6); the tasks' ``_set_obj_xyz`` writes
qpos[0:3] and zeroes qvel[9:15] (as MetaWorld does: those are arm and gripper velocities, the
mug keeps its own). The ``coffee_machine`` body moves per episode.

- coffee-button: the vector is the machine's position, the mug goes 0.22 m in front of it;
  the goal is the button's pressed position (machine + (0, -0.19, 0.3)). Observed object: the
  ``buttonStart`` site, quaternion (1, 0, 0, 0). Success: observed y within 0.02 of the goal's.
- coffee-pull / coffee-push: the vector is (mug xyz, goal xyz), redrawn while their xy are
  closer than 0.15 m; the machine goes 0.22 m behind the mug (pull) or the goal (push).
  Observed object: the ``obj`` body and the ``mug`` geom's orientation as scipy's quaternion
  (x-y-z-w). Success: the observed mug within 0.07 m of the goal.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    FreeObjectTask,
    MirrorTask,
    ModelFacts,
    View,
    gripper_caging,
    hamacher_product,
    matrix_quat,
    tolerance,
)
from openral_mjx.benchmarks.metaworld.mirror.tasks.button import front_press_reward

MUG_QPOS = 0  # the mug's free joint position (qpos[0:3])
ZEROED_QVEL = slice(9, 15)  # what the coffee tasks' `_set_obj_xyz` zeroes
MACHINE_TO_MUG = (0.0, -0.22, 0.0)


def _set_mug(qpos: jax.Array, qvel: jax.Array, pos: jax.Array) -> tuple[jax.Array, jax.Array]:
    return qpos.at[MUG_QPOS : MUG_QPOS + 3].set(pos), qvel.at[ZEROED_QVEL].set(0.0)


class CoffeeButton(MirrorTask):
    name = "coffee-button-v3"
    xml = "sawyer_xyz/sawyer_coffee.xml"
    hand_init_pos = (0.0, 0.4, 0.2)
    reset_low = (-0.1, 0.8, -0.001)
    reset_high = (0.1, 0.9, 0.001)
    # obj box + (-/+0.001, -0.22 + 0.03, 0.299 / 0.301)
    goal_low = (-0.101, 0.61, 0.298)
    goal_high = (0.101, 0.71, 0.302)
    sites = ("buttonStart",)
    moved_bodies = ("coffee_machine",)

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos, qvel = _set_mug(qpos, qvel, vec + jnp.asarray(MACHINE_TO_MUG))
        return qpos, qvel, {"coffee_machine": vec}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {
            "target_pos": vec + jnp.array([0.0, -0.22 + 0.03, 0.3]),
            "obj_init_pos": vec,
            "obj_to_target_init": jnp.asarray(0.03, jnp.float32),  # MetaWorld's `max_dist`
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos("buttonStart"), jnp.array([1.0, 0.0, 0.0, 0.0])

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.abs(episode["target_pos"][1] - obs[5]) <= 0.02

    has_reward = True

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: button-press-v3's, the press measured against the button's 0.03 m
        travel (``obj_to_target_init``)."""
        return front_press_reward(obs, view, episode)


class _Mug(FreeObjectTask):
    xml = "sawyer_xyz/sawyer_coffee.xml"
    hand_init_pos = (0.0, 0.4, 0.2)
    bodies = ("obj", "leftpad", "rightpad")
    geoms = ("mug",)
    moved_bodies = ("coffee_machine",)
    success_radius = 0.07

    def _machine(self, vec: jax.Array) -> jax.Array:
        raise NotImplementedError

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos, qvel = _set_mug(qpos, qvel, vec[:3])
        return qpos, qvel, {"coffee_machine": self._machine(vec)}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("obj"), matrix_quat(view.geom_quat("mug"))

    has_reward = True

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2 (push and pull alike): the mug caged (medium density, 0.7 effort)
        times its approach to the goal (x and y weighted 2x), plus 1 + 5 x the approach while
        the open gripper is within 4 cm of it; 10 within 0.05 (weighted)."""
        obj, target = obs[4:7], episode["target_pos"]
        scale = jnp.asarray([2.0, 2.0, 1.0], jnp.float32)
        to_target = jnp.linalg.norm((obj - target) * scale)
        margin = jnp.linalg.norm((episode["obj_init_pos"] - target) * scale)
        in_place = tolerance(to_target, 0.05, margin)
        grasped = gripper_caging(
            view, episode, action, obj, 0.02, 0.05, 0.05, 0.7, density="medium", reach_radius=0.04
        )
        reward = hamacher_product(grasped, in_place)
        near = (jnp.linalg.norm(obj - view.tcp_center) < 0.04) & (obs[3] > 0)
        reward = jnp.where(near, reward + 1.0 + 5.0 * in_place, reward)
        return jnp.where(to_target < 0.05, 10.0, reward)


class CoffeePull(_Mug):
    name = "coffee-pull-v3"
    reset_low = (-0.05, 0.7, -0.001, -0.1, 0.55, -0.001)
    reset_high = (0.05, 0.75, 0.001, 0.1, 0.65, 0.001)
    goal_low = (-0.1, 0.55, -0.001)
    goal_high = (0.1, 0.65, 0.001)

    def _machine(self, vec: jax.Array) -> jax.Array:
        return vec[:3] - jnp.asarray(MACHINE_TO_MUG)


class CoffeePush(_Mug):
    name = "coffee-push-v3"
    reset_low = (-0.1, 0.55, -0.001, -0.05, 0.7, -0.001)
    reset_high = (0.1, 0.65, 0.001, 0.05, 0.75, 0.001)
    goal_low = (-0.05, 0.7, -0.001)
    goal_high = (0.05, 0.75, 0.001)

    def _machine(self, vec: jax.Array) -> jax.Array:
        return vec[3:6] - jnp.asarray(MACHINE_TO_MUG)


TASKS = (CoffeeButton(), CoffeePull(), CoffeePush())
