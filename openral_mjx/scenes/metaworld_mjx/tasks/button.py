"""button-press(-wall)-v3, button-press-topdown(-wall)-v3: a button in a box (MetaWorld 3.1.1).

The random vector is the ``box`` body's position (moved per episode); the goal is the box's
``hole`` site after placement. The front-facing variants also set the button's slide joint
(qpos 9) to 0 with its velocity zeroed (their ``_set_obj_xyz``); the top-down ones leave it.
Observed object: the ``button`` body's position plus the button's length (0.193 m) along its
axis, and its ``xquat`` (w-x-y-z). Success: the observed button within a task's tolerance of
the goal along the pressing axis (y for the front-facing, z for the top-down ones).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import jax
import jax.numpy as jnp

from openral_mjx.scenes.metaworld_mjx.task import MirrorTask, ModelFacts, View

BUTTON_QPOS = 9  # the button's slide joint (MetaWorld's `_set_obj_xyz` writes qpos[9]/qvel[9])


class _Button(MirrorTask):
    hand_init_pos = (0.0, 0.4, 0.2)
    goal_low = (-0.5, 0.40, 0.05)  # goal_space = the hand's box
    goal_high = (0.5, 1.0, 0.5)
    bodies = ("button",)
    sites = ("hole",)
    moved_bodies = ("box",)
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
        return {"target_pos": view.site_pos("hole"), "obj_init_pos": vec}

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


class ButtonPressWall(_Button):
    name = "button-press-wall-v3"
    xml = "sawyer_xyz/sawyer_button_press_wall.xml"
    reset_low = (-0.05, 0.85, 0.1149)
    reset_high = (0.05, 0.9, 0.1151)
    axis, tolerance, reset_joint = 1, 0.03, True


class ButtonPressTopdown(_Button):
    name = "button-press-topdown-v3"
    xml = "sawyer_xyz/sawyer_button_press_topdown.xml"
    reset_low = (-0.1, 0.8, 0.115)
    reset_high = (0.1, 0.9, 0.115)
    axis, tolerance, reset_joint = 2, 0.024, False


class ButtonPressTopdownWall(ButtonPressTopdown):
    """button-press-topdown-v3 with a wall: the same box, axis and tolerance."""

    name = "button-press-topdown-wall-v3"
    xml = "sawyer_xyz/sawyer_button_press_topdown_wall.xml"


TASKS = (ButtonPress(), ButtonPressWall(), ButtonPressTopdown(), ButtonPressTopdownWall())
