"""door-open-v3, door-close-v3, door-lock-v3 (MetaWorld 3.1.1).

door-open / door-close (``sawyer_door_pull.xml``): the vector is the ``door`` body's position
(moved per episode); the door's hinge (``doorjoint``) is set closed (0, open) or open
(-1.5708, close) with its velocity zeroed. Observed object: the ``handle`` geom's position and
orientation as scipy's quaternion (x-y-z-w). Goal: door + (-0.3, -0.45, 0) (open) or
door + (0.2, -0.2, 0) (close). Success: open, the observed handle's x within 0.08 of the
goal's; close, the observed handle within 0.08 m of the goal.

door-lock (``sawyer_door_lock.xml``): the vector is the ``door`` body's position; the goal is
the lock body's placed position + (0, -0.04, -0.1). Observed object: the ``lockStartLock``
site and the ``door_link`` body's ``xquat`` (w-x-y-z). Success: observed z within 0.02 of the
goal's. MetaWorld steps the physics 5 times (``frame_skip``) after moving the door and reads
the lock's position there; the mirror starts from the placed state without those steps.
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
    matrix_quat,
    tolerance,
)


class _DoorPull(MirrorTask):
    xml = "sawyer_xyz/sawyer_door_pull.xml"
    reset_low = (0.0, 0.85, 0.15)
    reset_high = (0.1, 0.95, 0.15)
    geoms = ("handle",)
    moved_bodies = ("door",)
    door_angle: ClassVar[float]
    goal_offset: ClassVar[tuple[float, float, float]]

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        a, d = facts.qpos_adr["doorjoint"], facts.dof_adr["doorjoint"]
        qpos, qvel = qpos.at[a].set(self.door_angle), qvel.at[d].set(0.0)
        return qpos, qvel, {"door": vec}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {"target_pos": vec + jnp.asarray(self.goal_offset), "obj_init_pos": vec}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.geom_pos("handle"), matrix_quat(view.geom_quat("handle"))


class DoorOpen(_DoorPull):
    name = "door-open-v3"
    hand_init_pos = (0.0, 0.6, 0.2)
    goal_low = (-0.3, 0.4, 0.1499)
    goal_high = (-0.2, 0.5, 0.1501)
    door_angle = 0.0
    goal_offset = (-0.3, -0.45, 0.0)

    has_reward = True

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.abs(obs[4] - episode["target_pos"][0]) <= 0.08

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: the hand kept above a funnel around the handle while it moves in
        beside it, through the grip effort (2), and the door opened (8); 10 on success."""
        hand, door = obs[:3], obs[4:7] + jnp.asarray([-0.05, 0.0, 0.0], jnp.float32)
        radius = jnp.linalg.norm(hand[:2] - door[:2])
        floor = jnp.where(
            radius <= 0.12, 0.0, 0.04 * jnp.log(jnp.maximum(radius - 0.12, 1e-30)) + 0.4
        )
        above = jnp.where(hand[2] >= floor, 1.0, tolerance(floor - hand[2], 0.01, floor / 2.0))
        beside = jnp.asarray([0.05, 0.03, -0.01], jnp.float32)
        in_place = tolerance(jnp.linalg.norm(hand - door - beside), 0.06, 0.5)
        ready = hamacher_product(above, in_place)
        theta = view.qpos("doorjoint")
        opened = 0.2 * (theta < -jnp.pi / 90.0) + 0.8 * tolerance(
            jnp.pi / 2.0 + jnp.pi / 6.0 + theta, 0.5, jnp.pi / 3.0
        )
        grab = (jnp.clip(action[3], -1.0, 1.0) + 1.0) / 2.0
        reward = 2.0 * hamacher_product(ready, grab) + 8.0 * opened
        return jnp.where(self.success(obs, view, episode), 10.0, reward)


class DoorClose(_DoorPull):
    name = "door-close-v3"
    hand_init_pos = (-0.5, 0.6, 0.2)
    goal_low = (0.2, 0.65, 0.1499)
    goal_high = (0.3, 0.75, 0.1501)
    door_angle = -1.5708
    goal_offset = (0.2, -0.2, 0.0)
    has_reward = True

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: the tcp at the goal (3) and the handle at it (6), gaussian; 10
        within 0.05."""
        obj, target = obs[4:7], episode["target_pos"]
        to_target = jnp.linalg.norm(obj - target)
        margin = jnp.linalg.norm(episode["obj_init_pos"] - target)
        in_place = tolerance(to_target, 0.05, margin, "gaussian")
        hand_margin = jnp.linalg.norm(jnp.asarray(self.hand_init_pos) - obj) + 0.1
        tcp_to_target = jnp.linalg.norm(view.tcp_center - target)
        hand = tolerance(tcp_to_target, 0.25 * 0.05, hand_margin, "gaussian")
        return jnp.where(to_target < 0.05, 10.0, 3.0 * hand + 6.0 * in_place)

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= 0.08


class DoorLock(MirrorTask):
    name = "door-lock-v3"
    xml = "sawyer_xyz/sawyer_door_lock.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    hand_low = (-0.5, 0.40, -0.15)
    hand_high = (0.5, 1.0, 0.5)
    reset_low = (-0.1, 0.8, 0.15)
    reset_high = (0.1, 0.85, 0.15)
    goal_low = hand_low  # goal_space = the hand's box
    goal_high = hand_high
    bodies = ("lock_link", "door_link", "leftpad")
    sites = ("lockStartLock",)
    has_reward = True
    moved_bodies = ("door",)
    hand_reset_per_episode = True  # the arm brushes the moved lock on some seeds
    settle_steps = 1  # MetaWorld steps `frame_skip` times, then reads the lock's position

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        return qpos, qvel, {"door": vec}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        lock = view.body_pos("lock_link")
        return {"target_pos": lock + jnp.array([0.0, -0.04, -0.1]), "obj_init_pos": lock}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos("lockStartLock"), view.body_quat("door_link")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.abs(episode["target_pos"][2] - obs[6]) <= 0.02

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: 2 x (the gripper open) x (the left pad at the lock, x weighted 1/4
        and z 1/2), 8 x the lock pressed down (margin: the lock's length, 0.1). The pad's
        margin is MetaWorld's ``init_left_pad``, a live view of the pad's current position,
        so it is the current distance itself."""
        obj = obs[4:7]
        scale = jnp.asarray([0.25, 1.0, 0.5], jnp.float32)
        to_pad = jnp.linalg.norm((obj - view.body_pos("leftpad")) * scale)
        near = tolerance(to_pad, 0.01, to_pad)
        pressed = tolerance(jnp.abs(episode["target_pos"][2] - obj[2]), 0.005, 0.1)
        return 2.0 * hamacher_product(jnp.maximum(obs[3], 0.0), near) + 8.0 * pressed


TASKS = (DoorOpen(), DoorClose(), DoorLock())
