"""button-press(-wall)-v3, button-press-topdown(-wall)-v3: a button in a box (MetaWorld 3.1.1).

The random vector is the ``box`` body's position (moved per episode); the goal is the box's
``hole`` site after placement. The front-facing variants also set the button's slide joint
(qpos 9) to 0 with its velocity zeroed (their ``_set_obj_xyz``); the top-down ones leave it.
Observed object: the ``button`` body's position plus the button's length (0.193 m) along its
axis, and its ``xquat`` (w-x-y-z). Success: the observed button within a task's tolerance of
the goal along the pressing axis (y for the front-facing, z for the top-down ones).

Rewards (MetaWorld's v2, one formula per task): the tcp near the button (long tail, with the
gripper's opening as each task reads it) and the button pressed towards the hole along the
axis (long tail, margin: the ``buttonStart`` site's distance to the hole at reset).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    MirrorTask,
    ModelFacts,
    View,
    hamacher_product,
    tolerance,
)

BUTTON_QPOS = 9  # the button's slide joint (MetaWorld's `_set_obj_xyz` writes qpos[9]/qvel[9])


def press_terms(
    obs: jax.Array, view: View, episode: Mapping[str, Any], axis: int, near_radius: float
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(tcp to button, tcp near the button, button pressed) of MetaWorld's button rewards: the
    button is ``obs[4:7]``, pressed along `axis` towards ``episode["target_pos"]`` within
    5 mm, its margin ``episode["obj_to_target_init"]``."""
    obj = obs[4:7]
    tcp_to_obj = jnp.linalg.norm(obj - view.tcp_center)
    near = tolerance(tcp_to_obj, near_radius, jnp.linalg.norm(obj - episode["init_tcp"]))
    to_target = jnp.abs(episode["target_pos"][axis] - obj[axis])
    pressed = tolerance(to_target, 0.005, episode["obj_to_target_init"])
    return tcp_to_obj, near, pressed


def front_press_reward(obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
    """MetaWorld's v2 reward of button-press-v3 (coffee-button-v3 has the same): the open
    gripper near the button (2), and the button pressed along y once within 5 cm (8)."""
    tcp_to_obj, near, pressed = press_terms(obs, view, episode, axis=1, near_radius=0.05)
    reward = 2.0 * hamacher_product(jnp.maximum(obs[3], 0.0), near)
    return reward + jnp.where(tcp_to_obj <= 0.05, 8.0 * pressed, 0.0)


class _Button(MirrorTask):
    hand_init_pos = (0.0, 0.4, 0.2)
    goal_low = (-0.5, 0.40, 0.05)  # goal_space = the hand's box
    goal_high = (0.5, 1.0, 0.5)
    bodies = ("button",)
    sites = ("hole", "buttonStart")
    moved_bodies = ("box",)
    has_reward = True
    axis: ClassVar[int]  # pressing axis: 1 (y) front-facing, 2 (z) top-down
    tolerance: ClassVar[float]
    reset_joint: ClassVar[bool]

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        if self.reset_joint:
            qpos, qvel = qpos.at[BUTTON_QPOS].set(0.0), qvel.at[BUTTON_QPOS].set(0.0)
        return qpos, qvel, {"box": vec}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        a = self.axis
        hole = view.site_pos("hole")
        return {
            "target_pos": hole,
            "obj_init_pos": vec,
            "obj_to_target_init": jnp.abs(hole[a] - view.site_pos("buttonStart")[a]),
        }

    def _terms(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any]
    ) -> tuple[jax.Array, jax.Array, jax.Array]:
        """`press_terms` along this task's axis, near within 1 cm."""
        return press_terms(obs, view, episode, self.axis, near_radius=0.01)

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        offset = jnp.zeros(3).at[self.axis].set(-0.193 if self.axis == 1 else 0.193)
        return view.body_pos("button") + offset, view.body_quat("button")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        a = self.axis
        return jnp.abs(episode["target_pos"][a] - obs[4 + a]) <= self.tolerance


class ButtonPress(_Button):
    name = "button-press-v3"
    xml = "sawyer_xyz/sawyer_button_press.xml"
    reset_low = (-0.1, 0.85, 0.115)
    reset_high = (0.1, 0.9, 0.115)
    axis, tolerance, reset_joint = 1, 0.02, True

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        return front_press_reward(obs, view, episode)


class ButtonPressWall(_Button):
    name = "button-press-wall-v3"
    xml = "sawyer_xyz/sawyer_button_press_wall.xml"
    reset_low = (-0.05, 0.85, 0.1149)
    reset_high = (0.05, 0.9, 0.1151)
    axis, tolerance, reset_joint = 1, 0.03, True

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        tcp_to_obj, near, pressed = self._terms(obs, view, episode)
        far = 2.0 * hamacher_product((1.0 - obs[3]) / 2.0, near)
        return jnp.where(tcp_to_obj > 0.07, far, 2.0 + 2.0 * (1.0 + obs[3]) + 4.0 * pressed**2)


class ButtonPressTopdown(_Button):
    name = "button-press-topdown-v3"
    xml = "sawyer_xyz/sawyer_button_press_topdown.xml"
    reset_low = (-0.1, 0.8, 0.115)
    reset_high = (0.1, 0.9, 0.115)
    axis, tolerance, reset_joint = 2, 0.024, False

    def _closed(self, obs: jax.Array) -> jax.Array:
        return 1.0 - obs[3]

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        tcp_to_obj, near, pressed = self._terms(obs, view, episode)
        reward = 5.0 * hamacher_product(self._closed(obs), near)
        return reward + jnp.where(tcp_to_obj <= 0.03, 5.0 * pressed, 0.0)


class ButtonPressTopdownWall(ButtonPressTopdown):
    """button-press-topdown-v3 with a wall: the same box, axis and tolerance."""

    name = "button-press-topdown-wall-v3"
    xml = "sawyer_xyz/sawyer_button_press_topdown_wall.xml"

    def _closed(self, obs: jax.Array) -> jax.Array:
        return jnp.maximum(obs[3], 0.0)  # MetaWorld's wall variant reads the opening as is


TASKS = (ButtonPress(), ButtonPressWall(), ButtonPressTopdown(), ButtonPressTopdownWall())
