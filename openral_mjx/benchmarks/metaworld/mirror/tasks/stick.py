"""stick-push-v3, stick-pull-v3: push or pull the container with a stick (MetaWorld 3.1.1).

Both draw (stick xyz, goal xyz), redrawn while their xy are closer than 0.1. The stick's free
joint goes to the drawn xy at z 0.02 (velocities zeroed), the container's two slides (qpos 16,
17) to (0, 0) for push, (0, 0.09) for pull; MetaWorld zeroes qvel[16:18], which is the second
slide's velocity only (the slides' dofs are 15 and 16). Goal: the drawn xy at the rest height
of the ``insertion`` site (push) or at 0.02 (pull). Observed objects: the ``stick`` body (its
orientation as scipy's quaternion) and the ``insertion`` site (+0.09 in y for push) with a zero
quaternion.

Success, pull: the observed handle within 0.12 of the goal with the ``stick_end`` site at or
beyond it in x and within 0.04 in y, 0.06 in z. Push: the observed container within 0.12 of
the goal and MetaWorld's grasp check: gripper open (obs[3] > 0), stick 1 cm above its start
(0.02), and both pads pressing on the stick (``touching_main_object``, a contact-force test the
mirror cannot read: it is taken as true, see `StickPush.success`).
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
    gripper_caging,
    hamacher_product,
    matrix_quat,
    tolerance,
)

STICK_QPOS, STICK_DOF = 9, 9  # `_set_stick_xyz`: qpos[9:12], qvel[9:15]
SLIDES_QPOS = 16  # `_set_obj_xyz`: qpos[16:18], qvel[16:18]
STICK_Z = 0.02  # init_config["stick_init_pos"][-1]


class _Stick(MirrorTask):
    xml = "sawyer_xyz/sawyer_stick_obj.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    bodies = ("stick", "object", "leftpad", "rightpad")
    sites = ("insertion", "stick_end")
    has_reward = True
    slides: ClassVar[tuple[float, float]]
    insertion_offset: ClassVar[tuple[float, float, float]] = (0.0, 0.0, 0.0)

    def accept(self, vec: jax.Array) -> jax.Array:
        return jnp.linalg.norm(vec[:2] - vec[3:5]) >= 0.1

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        stick = jnp.concatenate([vec[:2], jnp.full((1,), STICK_Z, vec.dtype)])
        qpos = qpos.at[STICK_QPOS : STICK_QPOS + 3].set(stick)
        qvel = qvel.at[STICK_DOF : STICK_DOF + 6].set(0.0)
        qpos = qpos.at[SLIDES_QPOS : SLIDES_QPOS + 2].set(jnp.asarray(self.slides))
        qvel = qvel.at[SLIDES_QPOS : SLIDES_QPOS + 2].set(0.0)  # as MetaWorld: dof 16 only
        return qpos, qvel, {}

    def _goal_z(self, facts: ModelFacts) -> float:
        raise NotImplementedError

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        z = jnp.full((1,), self._goal_z(facts), vec.dtype)
        return {
            "target_pos": jnp.concatenate([vec[3:5], z]),
            "stick_init_pos": jnp.concatenate([vec[:2], jnp.full((1,), STICK_Z, vec.dtype)]),
            # MetaWorld's ``obj_init_pos``: the box's (``object``) placed position
            "obj_init_pos": view.body_pos("object"),
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        pos = jnp.concatenate(
            [
                view.body_pos("stick"),
                view.site_pos("insertion") + jnp.asarray(self.insertion_offset),
            ]
        )
        quat = jnp.concatenate([matrix_quat(view.body_quat("stick")), jnp.zeros(4)])
        return pos, quat


class StickPush(_Stick):
    name = "stick-push-v3"
    reset_low = (-0.08, 0.58, 0.0, 0.399, 0.55, 0.1319)
    reset_high = (-0.03, 0.62, 0.001, 0.401, 0.6, 0.1321)
    goal_low = (0.399, 0.55, 0.1319)
    goal_high = (0.401, 0.6, 0.1321)
    slides = (0.0, 0.0)
    insertion_offset = (0.0, 0.09, 0.0)

    def _goal_z(self, facts: ModelFacts) -> float:
        # `_get_site_pos("insertion")[-1]` after the hand reset, before the placement
        return float(facts.rest["site:insertion"][2])

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        near = jnp.linalg.norm(obs[11:14] - episode["target_pos"]) <= 0.12
        # MetaWorld also requires `touching_main_object` (both pads' contact forces on the
        # stick positive), which the View cannot read: taken as true. With the stick lifted
        # 1 cm and the gripper open, the stick is in practice held between the pads.
        grasped = (obs[3] > 0) & (obs[6] - 0.01 > episode["stick_init_pos"][2])
        return near & grasped

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: the stick caged and gripped; once held lifted in an open grip,
        2 + 5 x the stick's approach to the goal + 3 x the container's, 10 with the
        container within 0.12 (the margins less that radius)."""
        radius = 0.12
        stick = obs[4:7] + jnp.asarray([0.015, 0.0, 0.0], jnp.float32)
        container, target = obs[11:14], episode["target_pos"]
        stick_margin = jnp.linalg.norm(episode["stick_init_pos"] - target) - radius
        stick_in_place = tolerance(jnp.linalg.norm(stick - target), radius, stick_margin)
        to_target = jnp.linalg.norm(container - target)
        box_margin = jnp.linalg.norm(episode["obj_init_pos"] - target) - radius
        box_in_place = tolerance(to_target, radius, box_margin)
        # stick-push's own caging reward measures from the stick's start, not the box's
        from_stick = {**episode, "obj_init_pos": episode["stick_init_pos"]}
        grasped = gripper_caging(view, from_stick, action, stick, 0.04, 0.05, 0.01)
        held = (jnp.linalg.norm(stick - view.tcp_center) < 0.02) & (obs[3] > 0)
        held = held & (stick[2] - 0.01 > episode["stick_init_pos"][2])
        pushing = jnp.where(
            to_target <= radius, 10.0, 2.0 + 5.0 * stick_in_place + 3.0 * box_in_place
        )
        return jnp.where(held, pushing, grasped)


class StickPull(_Stick):
    name = "stick-pull-v3"
    reset_low = (-0.1, 0.55, 0.0, 0.35, 0.45, 0.0199)
    reset_high = (0.0, 0.65, 0.001, 0.45, 0.55, 0.0201)
    goal_low = (0.35, 0.45, 0.0199)
    goal_high = (0.45, 0.55, 0.0201)
    hand_low = (-0.5, 0.35, 0.05)
    slides = (0.0, 0.09)

    def _goal_z(self, facts: ModelFacts) -> float:
        return STICK_Z

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        handle = obs[11:14]
        end = view.site_pos("stick_end")
        inserted = (
            (end[0] >= handle[0])
            & (jnp.abs(end[1] - handle[1]) <= 0.040)
            & (jnp.abs(end[2] - handle[2]) <= 0.060)
        )
        return (jnp.linalg.norm(handle - episode["target_pos"]) <= 0.12) & inserted

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: (the stick caged and gripped, or 1 once held lifted in an open
        grip) times its approach to the container (z weighted 2); once held, plus 1 and 5x
        that approach, or with the stick in the handle 6 + 2 x the stick's approach to the
        goal + the container's; 10 there with the handle within 0.12 of the goal."""
        radius = 0.05
        stick, handle, target = obs[4:7], obs[11:14], episode["target_pos"]
        ahead = jnp.asarray([0.05, 0.0, 0.0], jnp.float32)
        container, container_init = handle + ahead, episode["obj_init_pos"] + ahead
        stick_init = episode["stick_init_pos"]
        scale = jnp.asarray([1.0, 1.0, 2.0], jnp.float32)
        stick_in_place = tolerance(
            jnp.linalg.norm((stick - container) * scale),
            radius,
            jnp.linalg.norm((stick_init - container_init) * scale),
        )
        stick_at_goal = tolerance(
            jnp.linalg.norm(stick - target), radius, jnp.linalg.norm(stick_init - target)
        )
        box_in_place = tolerance(
            jnp.linalg.norm(container - target),
            radius,
            jnp.linalg.norm(episode["obj_init_pos"] - target),
        )
        grasped = gripper_caging(view, episode, action, stick, 0.014, 0.05, 0.01)
        held = (jnp.linalg.norm(stick - view.tcp_center) < 0.02) & (obs[3] > 0)
        held = held & (stick[2] - 0.01 > stick_init[2])
        both = hamacher_product(jnp.where(held, 1.0, grasped), stick_in_place)
        end = view.site_pos("stick_end")
        inserted = (
            (end[0] >= handle[0])
            & (jnp.abs(end[1] - handle[1]) <= 0.040)
            & (jnp.abs(end[2] - handle[2]) <= 0.060)
        )
        pulling = jnp.where(
            jnp.linalg.norm(handle - target) <= 0.12,
            10.0,
            6.0 + both + 2.0 * stick_at_goal + box_in_place,
        )
        held_reward = jnp.where(inserted, pulling, 1.0 + both + 5.0 * stick_in_place)
        return jnp.where(held, held_reward, both)


TASKS = (StickPush(), StickPull())
