"""lever-pull-v3: lift the lever upright (MetaWorld 3.1.1).

The reset moves the ``lever`` body to the drawn position (the lever's joint is left as the hand
reset leaves it); goal: drawn position + (0.12, 0, 0.45), observed clipped to the hand box (its
goal space). Observed object: the ``leverStart`` site and the ``objGeom`` orientation as
scipy's quaternion (x-y-z-w). Success: the lever's angle (minus ``LeverAxis``) within pi/24 of
pi/2.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    ModelFacts,
    MovedBodyTask,
    View,
    hamacher_product,
    matrix_quat,
    tolerance,
)

LEVER_RADIUS = 0.2


class LeverPull(MovedBodyTask):
    name = "lever-pull-v3"
    xml = "sawyer_xyz/sawyer_lever_pull.xml"
    hand_init_pos = (0.0, 0.4, 0.2)
    reset_low = (-0.1, 0.7, 0.0)
    reset_high = (0.1, 0.8, 0.0)
    goal_low = (-0.5, 0.40, -0.15)
    goal_high = (0.5, 1.0, 0.5)
    hand_low = (-0.5, 0.40, -0.15)
    hand_high = (0.5, 1.0, 0.5)
    sites = ("leverStart",)
    geoms = ("objGeom",)
    moved_bodies = ("lever",)
    has_reward = True

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {
            "target_pos": vec + jnp.array([0.12, 0.0, 0.25 + LEVER_RADIUS], vec.dtype),
            "lever_pos_init": vec + jnp.array([0.12, -LEVER_RADIUS, 0.25], vec.dtype),
            "obj_init_pos": vec,
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos("leverStart"), matrix_quat(view.geom_quat("objGeom"))

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        angle = -view.qpos("LeverAxis")
        return jnp.abs(angle - math.pi / 2.0) <= math.pi / 24

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: 10 x (the hand's shoulder, hand + (0, 0.055, 0.07), under the
        lever's end, x and z weighted 4) x (the lever's end at the goal)."""
        offset = jnp.asarray([0.0, 0.055, 0.07], jnp.float32)
        scale = jnp.asarray([4.0, 1.0, 4.0], jnp.float32)
        lever, start, target = obs[4:7], episode["lever_pos_init"], episode["target_pos"]
        shoulder = jnp.linalg.norm((obs[:3] + offset - lever) * scale)
        init = jnp.linalg.norm((episode["init_tcp"] + offset - start) * scale)
        ready = tolerance(shoulder, 0.02, init)
        in_place = tolerance(jnp.linalg.norm(lever - target), 0.04, jnp.linalg.norm(start - target))
        return 10.0 * hamacher_product(ready, in_place)


TASKS = (LeverPull(),)
