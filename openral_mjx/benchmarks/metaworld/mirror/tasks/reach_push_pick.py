"""reach-v3, push-v3, pick-place-v3: one free puck, a goal drawn with it (MetaWorld 3.1.1).

All three draw (object xyz, goal xyz) and redraw while the object's and the goal's xy are
closer than 0.15 m; the puck starts at the drawn position. Observed object: the ``obj`` body's
position and the ``objGeom`` orientation as scipy's quaternion (x-y-z-w).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    FreeObjectTask,
    ModelFacts,
    View,
    at_rest_height,
    gripper_caging,
    hamacher_product,
    matrix_quat,
    tolerance,
)


class _Puck(FreeObjectTask):
    """What the three tasks share."""

    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.6, 0.02, -0.1, 0.8, 0.05)
    reset_high = (0.1, 0.7, 0.02, 0.1, 0.9, 0.3)
    goal_low = (-0.1, 0.8, 0.05)
    goal_high = (0.1, 0.9, 0.3)
    bodies = ("obj",)
    geoms = ("objGeom",)

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("obj"), matrix_quat(view.geom_quat("objGeom"))


class Reach(_Puck):
    name = "reach-v3"
    xml = "sawyer_xyz/sawyer_reach_v3.xml"
    has_reward = True

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(view.tcp_center - episode["target_pos"]) <= 0.05

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        target = episode["target_pos"]
        margin = jnp.linalg.norm(jnp.asarray(self.hand_init_pos) - target)
        in_place = tolerance(jnp.linalg.norm(view.tcp_center - target), 0.05, margin)
        return 10.0 * in_place


class Push(_Puck):
    name = "push-v3"
    xml = "sawyer_xyz/sawyer_push_v3.xml"
    reset_low = (-0.1, 0.6, 0.02, -0.1, 0.8, 0.01)
    reset_high = (0.1, 0.7, 0.02, 0.1, 0.9, 0.02)
    goal_low = (-0.1, 0.8, 0.01)
    goal_high = (0.1, 0.9, 0.02)
    rest_key = "body:obj"  # the rest height the drawn xy are put at (`facts.rest`)
    success_radius = 0.05
    bodies = ("obj", "leftpad", "rightpad")
    has_reward = True

    def obj_init(self, facts: ModelFacts, vec: jax.Array) -> jax.Array:
        # `fix_extreme_obj_pos`: the drawn xy at the puck's rest height
        return at_rest_height(facts, vec[:2], self.rest_key)

    def target(self, facts: ModelFacts, vec: jax.Array, view: View) -> jax.Array:
        return at_rest_height(facts, vec[3:5], self.rest_key)

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: caging and gripping the puck (2x), and once the open gripper is
        within 2 cm of it, again that plus 1 plus the puck's approach to the goal (5x); 10
        within 0.05 of the goal."""
        obj, target = obs[4:7], episode["target_pos"]
        to_target = jnp.linalg.norm(obj - target)
        in_place = tolerance(to_target, 0.05, jnp.linalg.norm(episode["obj_init_pos"] - target))
        grasped = gripper_caging(view, episode, action, obj, 0.015, 0.05, 0.005)
        reward = 2.0 * grasped
        near = (jnp.linalg.norm(obj - view.tcp_center) < 0.02) & (obs[3] > 0)
        reward = jnp.where(near, 2.0 * reward + 1.0 + 5.0 * in_place, reward)
        return jnp.where(to_target < 0.05, 10.0, reward)


class PickPlace(_Puck):
    name = "pick-place-v3"
    xml = "sawyer_xyz/sawyer_pick_place_v3.xml"
    success_radius = 0.07
    bodies = ("obj", "leftpad", "rightpad")
    has_reward = True

    def _caging(
        self, view: View, episode: Mapping[str, Any], action: jax.Array, obj: jax.Array
    ) -> jax.Array:
        """pick-place's own ``_gripper_caging_reward``. Its margins read the pads' "initial"
        positions, which MetaWorld holds as views of the live data: the pads where they are."""
        left, right = view.body_pos("leftpad")[1], view.body_pos("rightpad")[1]
        margin_l = jnp.abs(jnp.abs(obj[1] - left) - 0.05)
        margin_r = jnp.abs(jnp.abs(obj[1] - right) - 0.05)
        caging_l = tolerance(left - obj[1], 0.05, margin_l, lower=0.015)
        caging_r = tolerance(obj[1] - right, 0.05, margin_r, lower=0.015)
        xz = jnp.asarray([0, 2])
        margin = jnp.linalg.norm(episode["obj_init_pos"][xz] - episode["init_tcp"][xz]) - 0.005
        caging_xz = tolerance(jnp.linalg.norm(view.tcp_center[xz] - obj[xz]), 0.005, margin)
        caging = hamacher_product(hamacher_product(caging_l, caging_r), caging_xz)
        gripping = jnp.where(caging > 0.97, jnp.clip(action[-1], 0.0, 1.0), 0.0)
        return (hamacher_product(caging, gripping) + caging) / 2.0

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: caging-and-gripping times the puck's approach to the goal, plus 1
        and 5x the approach once the open gripper holds it lifted 1 cm; 10 within 0.05."""
        obj, target, start = obs[4:7], episode["target_pos"], episode["obj_init_pos"]
        to_target = jnp.linalg.norm(obj - target)
        in_place = tolerance(to_target, 0.05, jnp.linalg.norm(start - target))
        reward = hamacher_product(self._caging(view, episode, action, obj), in_place)
        near = jnp.linalg.norm(obj - view.tcp_center) < 0.02
        lifted = near & (obs[3] > 0) & (obj[2] - 0.01 > start[2])
        reward = jnp.where(lifted, reward + 1.0 + 5.0 * in_place, reward)
        return jnp.where(to_target < 0.05, 10.0, reward)


TASKS = (Reach(), Push(), PickPlace())
