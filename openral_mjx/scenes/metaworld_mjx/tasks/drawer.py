"""drawer-close-v3, drawer-open-v3: the drawer on its slide (MetaWorld 3.1.1).

Both move the ``drawer`` body to the drawn position. drawer-close then pulls the drawer out
(its slide ``goal_slidey``, qpos 9, to -0.15; the velocity is left as it is) and aims at the
closed handle, drawn position + (0, -0.16, 0.09); it observes ``drawer_link`` + (0, -0.16,
0.05) with a zero quaternion and succeeds within 0.065 (MetaWorld reads the base class's
``TARGET_RADIUS`` 0.05, + 0.015). drawer-open leaves the slide and aims at drawn position
+ (0, -0.36, 0.09); it observes ``drawer_link`` + (0, -0.16, 0) with its ``xquat`` (w-x-y-z)
and succeeds within 0.03. Both observe the goal clipped to the hand box (their goal space).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.scenes.metaworld_mjx.task import MirrorTask, ModelFacts, View

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

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {"target_pos": vec + jnp.asarray(self.target_offset, vec.dtype)}

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


class DrawerOpen(_Drawer):
    name = "drawer-open-v3"
    target_offset = (0.0, -0.16 - 0.2, 0.09)
    obj_offset = (0.0, -0.16, 0.0)
    radius = 0.03

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        return qpos, qvel, {"drawer": vec}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return self._handle(view), view.body_quat("drawer_link")


TASKS = (DrawerClose(), DrawerOpen())
