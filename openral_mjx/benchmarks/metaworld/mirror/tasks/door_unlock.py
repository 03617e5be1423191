"""door-unlock-v3: turn the door's lock from locked to unlocked (MetaWorld 3.1.1).

The reset moves the ``door`` body to the drawn position and sets the lock's hinge (the
model's unnamed joint at qpos 9) to 1.5708 with its velocity zeroed; the goal is the lock
body's placed position plus (0.1, -0.04, 0). Observed object: the ``lockStartUnlock`` site
and the ``door_link`` body's ``xquat`` (w-x-y-z). Success: the observed lock's x within 0.02
of the goal's x.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import MirrorTask, ModelFacts, View, tolerance

LOCK_QPOS = 9  # MetaWorld's `_set_obj_xyz` writes qpos[9] / qvel[9] (the lock's hinge)


class DoorUnlock(MirrorTask):
    name = "door-unlock-v3"
    xml = "sawyer_xyz/sawyer_door_lock.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.8, 0.15)
    reset_high = (0.1, 0.85, 0.15)
    goal_low = (0.0, 0.64, 0.2100)
    goal_high = (0.2, 0.7, 0.2111)
    hand_low = (-0.5, 0.40, -0.15)
    hand_high = (0.5, 1.0, 0.5)
    bodies = ("lock_link", "door_link")
    sites = ("lockStartUnlock",)
    moved_bodies = ("door",)
    hand_reset_per_episode = True  # the hand meets the lock for ~30% of door positions
    has_reward = True

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos = qpos.at[LOCK_QPOS].set(1.5708)
        qvel = qvel.at[LOCK_QPOS].set(0.0)
        return qpos, qvel, {"door": vec}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        lock = view.body_pos("lock_link")
        return {"target_pos": lock + jnp.array([0.1, -0.04, 0.0]), "obj_init_pos": lock}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.site_pos("lockStartUnlock"), view.body_quat("door_link")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.abs(episode["target_pos"][0] - obs[4]) <= 0.02

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: 2 x the hand's shoulder (hand + (0, 0.055, 0.07)) at the lock (x
        weighted 1/4, z 1/2), 8 x the lock pushed to the goal's x (margin 0.1)."""
        offset = jnp.asarray([0.0, 0.055, 0.07], jnp.float32)
        scale = jnp.asarray([0.25, 1.0, 0.5], jnp.float32)
        lock = obs[4:7]
        shoulder = jnp.linalg.norm((obs[:3] + offset - lock) * scale)
        init = jnp.linalg.norm((episode["init_tcp"] + offset - episode["obj_init_pos"]) * scale)
        ready = tolerance(shoulder, 0.02, init)
        pushed = tolerance(jnp.abs(episode["target_pos"][0] - lock[0]), 0.005, 0.1)
        return 2.0 * ready + 8.0 * pushed


TASKS = (DoorUnlock(),)
