"""peg-insert-side-v3, peg-unplug-side-v3: the peg and its box, side-on (MetaWorld 3.1.1).

peg-insert-side draws (peg xyz, box xyz), redrawn while their xy are closer than 0.1: the peg's
free joint goes to the drawn position (orientation and angular state kept, velocities zeroed),
the ``box`` body to the drawn box position; goal: box + (0.03, 0, 0.13). Observed object: the
``pegGrasp`` site and the peg's orientation (the site's frame is the body's) as scipy's
quaternion; success: the ``pegHead`` site within 0.07 of the goal, with y and z weighted 2.

peg-unplug-side draws the box position: the ``box`` body goes there, the plug's free joint to
box + (0.044, 0, 0.131) with identity orientation and zero linear velocity; MetaWorld leaves
the angular velocity as its last hand reset left it, which knocks the plug about inside the
moved box, so the mirror simulates that hand reset per episode; goal: plug + (0.15, 0, 0).
Observed object: the ``pegEnd`` site and the ``plug1`` body's quaternion as MuJoCo's
(w-x-y-z); success: within 0.07 of goal.
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
    hamacher_product,
    matrix_quat,
    tolerance,
)

FREE_QPOS, FREE_DOF = 9, 9  # MetaWorld's `_set_obj_xyz` writes qpos[9:12], qvel[9:15]
INSERT_GOAL_OFFSET = (0.03, 0.0, 0.13)
# Corners of the two boxes beside the hole, where MetaWorld's reward fades as the peg's head
# nears the wall (`rect_prism_tolerance`): (the corner where it is 0, the corner where 1)
COLLISION_BOXES = tuple(
    (f"bottom_right_corner_collision_box_{i}", f"top_left_corner_collision_box_{i}") for i in (1, 2)
)


def rect_prism_tolerance(curr: jax.Array, zero: jax.Array, one: jax.Array) -> jax.Array:
    """MetaWorld's ``reward_utils.rect_prism_tolerance``: inside the box spanned by corners
    `zero` and `one`, the product of `curr`'s fractions of the way from `zero` to `one` per
    axis; outside it, 1."""
    inside = jnp.all((curr >= jnp.minimum(zero, one)) & (curr <= jnp.maximum(zero, one)))
    return jnp.where(inside, jnp.prod((curr - zero) / (one - zero)), 1.0)


PLUG_OFFSET = (0.044, 0.0, 0.131)
UNPLUG_GOAL_OFFSET = (0.15, 0.0, 0.0)


class PegInsertSide(MirrorTask):
    name = "peg-insert-side-v3"
    xml = "sawyer_xyz/sawyer_peg_insertion_side.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (0.0, 0.5, 0.02, -0.35, 0.4, -0.001)
    reset_high = (0.2, 0.7, 0.02, -0.25, 0.7, 0.001)
    goal_low = (-0.35 + 0.03, 0.4, -0.001 + 0.13)
    goal_high = (-0.25 + 0.03, 0.7, 0.001 + 0.13)
    bodies = ("peg", "leftpad", "rightpad")
    sites = ("pegGrasp", "pegHead", *(s for box in COLLISION_BOXES for s in box))
    moved_bodies = ("box",)
    has_reward = True

    def accept(self, vec: jax.Array) -> jax.Array:
        return jnp.linalg.norm(vec[:2] - vec[3:5]) >= 0.1

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[FREE_QPOS : FREE_QPOS + 3].set(vec[:3])
        qvel = qvel.at[FREE_DOF : FREE_DOF + 6].set(0.0)
        return qpos, qvel, {"box": vec[3:6]}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {
            "target_pos": vec[3:6] + jnp.asarray(INSERT_GOAL_OFFSET),
            "obj_init_pos": vec[:3],
            # read after the hand reset, before the peg is placed
            "peg_head_pos_init": jnp.asarray(facts.rest["site:pegHead"], jnp.float32),
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos("pegGrasp"), matrix_quat(view.body_quat("peg"))

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        scale = jnp.asarray((1.0, 2.0, 2.0))
        head = view.site_pos("pegHead")
        return jnp.linalg.norm((head - episode["target_pos"]) * scale) <= 0.07

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: the peg caged and gripped (or held lifted), times its head's
        approach to the hole (y and z weighted 2x) faded near the wall's boxes, plus 1 and 5x
        that approach while it is held lifted; 10 once inserted."""
        obj, target, start = obs[4:7], episode["target_pos"], episode["obj_init_pos"]
        scale = jnp.asarray([1.0, 2.0, 2.0], jnp.float32)
        head = view.site_pos("pegHead")
        to_target = jnp.linalg.norm((head - target) * scale)
        margin = jnp.linalg.norm((episode["peg_head_pos_init"] - target) * scale)
        boxes = [
            rect_prism_tolerance(head, view.site_pos(zero), view.site_pos(one))
            for zero, one in COLLISION_BOXES
        ]
        in_place = hamacher_product(
            tolerance(to_target, 0.07, margin), hamacher_product(boxes[1], boxes[0])
        )
        tcp_to_obj = jnp.linalg.norm(obj - view.tcp_center)
        held = (tcp_to_obj < 0.08) & (obs[3] > 0) & (obj[2] - 0.01 > start[2])
        caged = gripper_caging(view, episode, action, obj, 0.0075, 0.03, 0.005)
        reward = hamacher_product(jnp.where(held, 1.0, caged), in_place)
        reward = jnp.where(held, reward + 1.0 + 5.0 * in_place, reward)
        return jnp.where(to_target <= 0.07, 10.0, reward)


class PegUnplugSide(MirrorTask):
    name = "peg-unplug-side-v3"
    xml = "sawyer_xyz/sawyer_peg_unplug_side.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.25, 0.6, -0.001)
    reset_high = (-0.15, 0.8, 0.001)
    goal_low = (-0.25 + 0.194, 0.6, -0.001 + 0.131)
    goal_high = (-0.15 + 0.194, 0.8, 0.001 + 0.131)
    bodies = ("plug1", "leftpad", "rightpad")
    sites = ("pegEnd",)
    moved_bodies = ("box",)
    has_reward = True
    # MetaWorld's final hand reset runs with the box already moved and the plug at its model
    # default, inside the moved box: the plug is knocked about, and `_set_obj_xyz` keeps the
    # angular velocity it leaves (qvel[12:15]), so that velocity depends on the episode
    hand_reset_per_episode = True

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        plug = vec[:3] + jnp.asarray(PLUG_OFFSET)
        qpos = qpos.at[FREE_QPOS : FREE_QPOS + 3].set(plug)
        qpos = qpos.at[FREE_QPOS + 3 : FREE_QPOS + 7].set(jnp.asarray((1.0, 0.0, 0.0, 0.0)))
        qvel = qvel.at[FREE_DOF : FREE_DOF + 3].set(0.0)
        return qpos, qvel, {"box": vec[:3]}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        plug = vec[:3] + jnp.asarray(PLUG_OFFSET)
        return {
            "target_pos": plug + jnp.asarray(UNPLUG_GOAL_OFFSET),
            "obj_init_pos": view.site_pos("pegEnd"),
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos("pegEnd"), view.body_quat("plug1")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= 0.07

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: 2 x the plug caged and gripped (effort 0.8); 1 + 2 x that + 5 x
        its approach to the goal once pulled 1.5 cm in an open grip; 10 within 0.05."""
        obj, target, start = obs[4:7], episode["target_pos"], episode["obj_init_pos"]
        grasped = gripper_caging(view, episode, action, obj, 0.025, 0.05, 0.005, effort=0.8)
        to_target = jnp.linalg.norm(obj - target)
        in_place = tolerance(to_target, 0.05, jnp.linalg.norm(start - target))
        pulled = (obs[3] > 0.5) & (obj[0] - start[0] > 0.015)
        pulled = pulled & (jnp.linalg.norm(obj - view.tcp_center) < 0.035)
        reward = jnp.where(pulled, 1.0 + 2.0 * grasped + 5.0 * in_place, 2.0 * grasped)
        return jnp.where(to_target <= 0.05, 10.0, reward)


TASKS = (PegInsertSide(), PegUnplugSide())
