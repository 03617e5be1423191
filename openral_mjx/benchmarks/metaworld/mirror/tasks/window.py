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

Reward (MetaWorld's v2): 10 x the Hamacher product of the tcp's reach to the handle (within
2 cm; long tail for open, gaussian for close) and the handle's x distance to the goal (within
0.05; its margin from the window's drawn x for open, the handle's for close). The reach margin
uses MetaWorld's ``window_handle_pos_init``: the handle with the window moved, read before the
slide is written (+ 0.2 m in x for close), which is where the placed slide puts it.
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


class _Window(MirrorTask):
    xml = "sawyer_xyz/sawyer_window_horizontal.xml"
    hand_init_pos = (0.0, 0.4, 0.2)
    goal_low = (-0.5, 0.40, 0.05)  # the hand's box
    goal_high = (0.5, 1.0, 0.5)
    moved_bodies = ("window",)
    observes_before_place = True
    has_reward = True
    handle: ClassVar[str]
    slide: ClassVar[float]
    goal_offset: ClassVar[tuple[float, float, float]]
    reach_sigmoid: ClassVar[str]
    # where the in-place term's margin is measured from: the window (open) or the handle (close)
    in_place_from: ClassVar[str]

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[facts.qpos_adr["window_slide"]].set(self.slide)
        return qpos, qvel, {"window": vec[:3]}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {
            "target_pos": vec[:3] + jnp.asarray(self.goal_offset, vec.dtype),
            "obj_init_pos": vec[:3],
            # MetaWorld's `window_handle_pos_init`: the handle before the slide is written (at
            # the hand reset's 0), + 0.2 m in x for close: where the slide, along x, puts it
            "handle_init": view.site_pos(self.handle),
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos(self.handle), jnp.zeros(4, jnp.float32)

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.abs(view.site_pos(self.handle)[0] - episode["target_pos"][0]) <= 0.05

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        del obs, action
        obj, target = view.site_pos(self.handle), episode["target_pos"]
        start = episode["handle_init"]
        to_target = jnp.abs(obj[0] - target[0])
        from_x = episode[self.in_place_from][0]
        in_place = tolerance(to_target, 0.05, jnp.abs(jnp.abs(from_x - target[0]) - 0.05))
        tcp_to_obj = jnp.linalg.norm(obj - view.tcp_center)
        tcp_to_obj_init = jnp.linalg.norm(start - episode["init_tcp"])
        reach = tolerance(tcp_to_obj, 0.02, jnp.abs(tcp_to_obj_init - 0.02), self.reach_sigmoid)
        return 10.0 * hamacher_product(reach, in_place)


class WindowOpen(_Window):
    name = "window-open-v3"
    reset_low = (-0.1, 0.7, 0.16)
    reset_high = (0.1, 0.9, 0.16)
    sites = ("handleOpenStart",)
    handle = "handleOpenStart"
    slide = 0.0
    goal_offset = (0.2, 0.0, 0.0)
    reach_sigmoid = "long_tail"
    in_place_from = "obj_init_pos"


class WindowClose(_Window):
    name = "window-close-v3"
    reset_low = (0.0, 0.75, 0.2)
    reset_high = (0.0, 0.9, 0.2)
    sites = ("handleCloseStart",)
    handle = "handleCloseStart"
    slide = 0.2
    goal_offset = (0.0, 0.0, 0.0)
    reach_sigmoid = "gaussian"
    in_place_from = "handle_init"


TASKS = (WindowOpen(), WindowClose())
