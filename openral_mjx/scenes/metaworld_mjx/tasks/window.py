"""window-open-v3, window-close-v3: slide the window open or shut (MetaWorld 3.1.1).

Both draw the window's position: the ``window`` body goes there and its ``window_slide`` joint
to 0 (open task) or 0.2 (close task), written into ``data.qpos`` directly (velocity kept). Goal:
the window + (0.2, 0, 0) (open) or the window (close). Observed object: the ``handleOpenStart``
(open) or ``handleCloseStart`` (close) site, with a zero quaternion. Success: that site within
0.05 of the goal in x.

MetaWorld writes the slide after the hand reset's last kinematics and reads its reset
observation without recomputing them, so that observation (and the first step's previous
frame) shows the handle at the slide's hand-reset position (≈ 0), 0.2 m from where the close
task's window starts. The mirror observes the same way (`observes_before_place`); the state,
and every later observation, is the placed one.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import jax
import jax.numpy as jnp

from openral_mjx.scenes.metaworld_mjx.task import MirrorTask, ModelFacts, View


class _Window(MirrorTask):
    xml = "sawyer_xyz/sawyer_window_horizontal.xml"
    hand_init_pos = (0.0, 0.4, 0.2)
    goal_low = (-0.5, 0.40, 0.05)  # the hand's box
    goal_high = (0.5, 1.0, 0.5)
    moved_bodies = ("window",)
    observes_before_place = True
    handle: ClassVar[str]
    slide: ClassVar[float]
    goal_offset: ClassVar[tuple[float, float, float]]

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[facts.qpos_adr["window_slide"]].set(self.slide)
        return qpos, qvel, {"window": vec[:3]}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {
            "target_pos": vec[:3] + jnp.asarray(self.goal_offset, vec.dtype),
            "obj_init_pos": vec[:3],
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos(self.handle), jnp.zeros(4, jnp.float32)

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.abs(view.site_pos(self.handle)[0] - episode["target_pos"][0]) <= 0.05


class WindowOpen(_Window):
    name = "window-open-v3"
    reset_low = (-0.1, 0.7, 0.16)
    reset_high = (0.1, 0.9, 0.16)
    sites = ("handleOpenStart",)
    handle = "handleOpenStart"
    slide = 0.0
    goal_offset = (0.2, 0.0, 0.0)


class WindowClose(_Window):
    name = "window-close-v3"
    reset_low = (0.0, 0.75, 0.2)
    reset_high = (0.0, 0.9, 0.2)
    sites = ("handleCloseStart",)
    handle = "handleCloseStart"
    slide = 0.2
    goal_offset = (0.0, 0.0, 0.0)


TASKS = (WindowOpen(), WindowClose())
