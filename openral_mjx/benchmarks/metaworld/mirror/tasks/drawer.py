"""drawer-close-v3, drawer-open-v3: the drawer on its slide (MetaWorld 3.1.1).

Both move the ``drawer`` body to the drawn position. drawer-close then pulls the drawer out
(its slide ``goal_slidey``, qpos 9, to -0.15; the velocity is left as it is) and aims at the
closed handle, drawn position + (0, -0.16, 0.09); it observes ``drawer_link`` + (0, -0.16,
0.05) with a zero quaternion and succeeds within 0.065 (MetaWorld reads the base class's
``TARGET_RADIUS`` 0.05, + 0.015). drawer-open leaves the slide and aims at drawn position
+ (0, -0.36, 0.09); it observes ``drawer_link`` + (0, -0.16, 0) with its ``xquat`` (w-x-y-z)
and succeeds within 0.03. Both observe the goal clipped to the hand box (their goal space).

Rewards (MetaWorld's v2): drawer-close, the gripper's reach to the handle (gaussian, within
5 mm, through the closing gripper) and the handle's distance to the closed position (long
tail), 10 within 0.065; drawer-open, caging the handle (xy weighted 3x) plus opening it, 5 each.
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
    hamacher_product,
    tolerance,
)

SLIDE_QPOS = 9  # MetaWorld's drawer-close `_set_obj_xyz` writes qpos[9]


class _Drawer(MirrorTask):
    xml = "sawyer_xyz/sawyer_drawer.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.9, 0.0)
    reset_high = (0.1, 0.9, 0.0)
    goal_low = (-0.5, 0.40, 0.05)
    goal_high = (0.5, 1.0, 0.5)
    bodies = ("drawer_link",)
    moved_bodies = ("drawer",)
    target_offset: tuple[float, float, float]
    obj_offset: tuple[float, float, float]
    radius: float

    has_reward = True

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {
            "target_pos": vec + jnp.asarray(self.target_offset, vec.dtype),
            "obj_init_pos": self._handle(view),  # the handle where the reset leaves it
        }

    def _handle(self, view: View) -> jax.Array:
        return view.body_pos("drawer_link") + jnp.asarray(self.obj_offset, jnp.float32)

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= self.radius


class DrawerClose(_Drawer):
    name = "drawer-close-v3"
    target_offset = (0.0, -0.16, 0.09)
    obj_offset = (0.0, -0.16, 0.05)
    radius = 0.05 + 0.015

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        return qpos.at[SLIDE_QPOS].set(-0.15), qvel, {"drawer": vec}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return self._handle(view), jnp.zeros(4, jnp.float32)

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        obj, target, start = obs[4:7], episode["target_pos"], episode["obj_init_pos"]
        to_target = jnp.linalg.norm(obj - target)
        to_target_init = jnp.linalg.norm(start - target)
        in_place = tolerance(to_target, 0.05, jnp.abs(to_target_init - 0.05))
        tcp_to_obj = jnp.linalg.norm(obj - view.tcp_center)
        tcp_to_obj_init = jnp.linalg.norm(start - episode["init_tcp"])
        reach = tolerance(tcp_to_obj, 0.005, jnp.abs(tcp_to_obj_init - 0.005), "gaussian")
        reach = hamacher_product(reach, jnp.clip(action[-1], 0.0, 1.0))
        reward = jnp.where(to_target <= 0.05 + 0.015, 1.0, hamacher_product(reach, in_place))
        return 10.0 * reward


class DrawerOpen(_Drawer):
    name = "drawer-open-v3"
    target_offset = (0.0, -0.16 - 0.2, 0.09)
    obj_offset = (0.0, -0.16, 0.0)
    radius = 0.03

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        return qpos, qvel, {"drawer": vec}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        # drawer-open keeps ``obj_init_pos`` at the drawer's drawn position (drawer-close
        # re-reads it from the handle); its reward does not read it
        return {**super().episode(facts, vec, view), "obj_init_pos": vec}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return self._handle(view), view.body_quat("drawer_link")

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        del view, action
        max_dist = 0.2  # how far the drawer opens (MetaWorld's ``maxDist``)
        handle, target = obs[4:7], episode["target_pos"]
        opening = tolerance(jnp.linalg.norm(handle - target), 0.02, max_dist)
        handle_init = target + jnp.asarray([0.0, max_dist, 0.0], target.dtype)
        scale = jnp.asarray([3.0, 3.0, 1.0], jnp.float32)
        error = jnp.linalg.norm((handle - obs[:3]) * scale)
        error_init = jnp.linalg.norm((handle_init - episode["init_tcp"]) * scale)
        caging = tolerance(error, 0.01, error_init)
        return 5.0 * (caging + opening)


TASKS = (DrawerClose(), DrawerOpen())
