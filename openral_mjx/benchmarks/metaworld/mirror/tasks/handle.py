"""handle-press(-side)-v3, handle-pull(-side)-v3: the handle on its slide (MetaWorld 3.1.1).

All four move the ``box`` body to the drawn position and set the handle's slide (the model's
unnamed joint at qpos 9) with its velocity zeroed: -0.001 (press: up) or -0.1 (pull: down).
Goal: the ``goalPress`` / ``goalPull`` site after placement. Observed object: a site of the
handle (press: ``handleStart``, pull-side: ``handleCenter``, pull: ``handleRight``) with a
zero quaternion. Success: press, the ``handleStart`` site's height within 0.02 of the goal's
(read from the data, not the observation); pull-side, the observed handle within 0.08 of the
goal; pull, the observed handle's height within 0.05 (the base class's ``TARGET_RADIUS``).
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
    tolerance,
)

HANDLE_QPOS = 9  # MetaWorld's `_set_obj_xyz` writes qpos[9] / qvel[9] (the handle's slide)


class _Handle(MirrorTask):
    hand_init_pos = (0.0, 0.6, 0.2)
    moved_bodies = ("box",)
    hand_reset_per_episode = True  # the hand meets the handle for about half the boxes
    has_reward = True
    handle_qpos: float
    goal_site: str
    handle_site: str

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[HANDLE_QPOS].set(self.handle_qpos)
        qvel = qvel.at[HANDLE_QPOS].set(0.0)
        return qpos, qvel, {"box": vec}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {"target_pos": view.site_pos(self.goal_site), "obj_init_pos": vec}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos(self.handle_site), jnp.zeros(4, jnp.float32)


class _Press(_Handle):
    handle_qpos = -0.001
    goal_site = "goalPress"
    handle_site = "handleStart"
    sites = ("goalPress", "handleStart")

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {**super().episode(facts, vec, view), "handle_init": view.site_pos("handleStart")}

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.abs(view.site_pos("handleStart")[2] - episode["target_pos"][2]) <= 0.02

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: 10 x (the tcp at the handle) x (the handle's height at the
        goal's); 10 within 0.02."""
        handle, target, start = (
            view.site_pos("handleStart"),
            episode["target_pos"],
            episode["handle_init"],
        )
        to_target = jnp.abs(handle[2] - target[2])
        in_place = tolerance(to_target, 0.02, jnp.abs(jnp.abs(start[2] - target[2]) - 0.02))
        reach_margin = jnp.abs(jnp.linalg.norm(start - episode["init_tcp"]) - 0.02)
        reach = tolerance(jnp.linalg.norm(handle - view.tcp_center), 0.02, reach_margin)
        return 10.0 * jnp.where(to_target <= 0.02, 1.0, hamacher_product(reach, in_place))


class HandlePressSide(_Press):
    name = "handle-press-side-v3"
    xml = "sawyer_xyz/sawyer_handle_press_sideways.xml"
    reset_low = (-0.35, 0.65, -0.001)
    reset_high = (-0.25, 0.75, 0.001)
    goal_low = (-0.5, 0.40, 0.05)
    goal_high = (0.5, 1.0, 0.5)


class HandlePress(_Press):
    name = "handle-press-v3"
    xml = "sawyer_xyz/sawyer_handle_press.xml"
    reset_low = (-0.1, 0.8, -0.001)
    reset_high = (0.1, 0.9, 0.001)
    goal_low = (-0.1, 0.55, 0.04)
    goal_high = (0.1, 0.70, 0.08)


class _Pull(_Handle):
    handle_qpos = -0.1
    goal_site = "goalPull"
    bodies = ("leftpad", "rightpad")
    # (pad_success_thresh, obj_radius) of the caging reward
    caging: tuple[float, float]

    def to_target(self, obj: jax.Array, episode: Mapping[str, Any]) -> tuple[jax.Array, jax.Array]:
        """(the handle's distance to the goal, the same at the start)."""
        raise NotImplementedError

    def lifted(self, obj: jax.Array, episode: Mapping[str, Any]) -> jax.Array:
        """MetaWorld's test that the handle has moved up (pull adds 1 + 5 x in_place)."""
        raise NotImplementedError

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: the handle caged and gripped times its approach to the goal, plus 1
        and 5x that approach once held open and lifted; 10 within 0.05."""
        obj = obs[4:7]
        to_target, init = self.to_target(obj, episode)
        in_place = tolerance(to_target, 0.05, init)
        pad, radius = self.caging
        grasped = gripper_caging(view, episode, action, obj, radius, pad, 0.01)
        reward = hamacher_product(grasped, in_place)
        held = (jnp.linalg.norm(obj - view.tcp_center) < 0.035) & (obs[3] > 0)
        held = held & self.lifted(obj, episode)
        reward = jnp.where(held, reward + 1.0 + 5.0 * in_place, reward)
        return jnp.where(to_target < 0.05, 10.0, reward)


class HandlePullSide(_Pull):
    name = "handle-pull-side-v3"
    xml = "sawyer_xyz/sawyer_handle_press_sideways.xml"
    reset_low = (-0.35, 0.65, 0.0)
    reset_high = (-0.25, 0.75, 0.0)
    goal_low = (-0.5, 0.40, 0.05)
    goal_high = (0.5, 1.0, 0.5)
    sites = ("goalPull", "handleCenter")
    handle_site = "handleCenter"
    caging = (0.06, 0.032)

    def to_target(self, obj: jax.Array, episode: Mapping[str, Any]) -> tuple[jax.Array, jax.Array]:
        target = episode["target_pos"]
        return jnp.linalg.norm(obj - target), jnp.linalg.norm(episode["obj_init_pos"] - target)

    def lifted(self, obj: jax.Array, episode: Mapping[str, Any]) -> jax.Array:
        return obj[2] - 0.01 > episode["obj_init_pos"][2]

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        # MetaWorld re-reads ``obj_init_pos`` from the placed handle here
        return {**super().episode(facts, vec, view), "obj_init_pos": view.site_pos("handleCenter")}

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= 0.08


class HandlePull(_Pull):
    name = "handle-pull-v3"
    xml = "sawyer_xyz/sawyer_handle_press.xml"
    reset_low = (-0.1, 0.8, -0.001)
    reset_high = (0.1, 0.9, 0.001)
    goal_low = (-0.1, 0.55, 0.04)
    goal_high = (0.1, 0.70, 0.18)
    sites = ("goalPull", "handleRight")
    handle_site = "handleRight"
    caging = (0.05, 0.022)

    def to_target(self, obj: jax.Array, episode: Mapping[str, Any]) -> tuple[jax.Array, jax.Array]:
        target_z = episode["target_pos"][2]
        return jnp.abs(target_z - obj[2]), jnp.abs(target_z - episode["obj_init_pos"][2])

    def lifted(self, obj: jax.Array, episode: Mapping[str, Any]) -> jax.Array:
        # MetaWorld compares the handle's y with its start's z (sic)
        return obj[1] - 0.01 > episode["obj_init_pos"][2]

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.abs(episode["target_pos"][2] - obs[6]) <= 0.05


TASKS = (HandlePressSide(), HandlePress(), HandlePullSide(), HandlePull())
