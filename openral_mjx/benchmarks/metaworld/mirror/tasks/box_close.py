"""box-close-v3: put the lid on the box (MetaWorld 3.1.1).

The vector is (lid xyz, box xyz), redrawn while their xy are closer than 0.25 m. The ``boxbody``
body goes to the drawn box xy at its height after the hand reset; the lid's free joint
(qpos 9..11) goes to the drawn lid xy at height 0.02 (a float32), velocities zeroed. The goal
is the drawn box position. Observed object: the ``top_link`` body and its ``xquat``
(w-x-y-z). Success: the observed lid within 0.08 m of the goal. MetaWorld steps the physics 5
times (``frame_skip``) between moving the box and placing the lid, so the lid keeps the
orientation those steps leave it in (`settle_steps`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.benchmarks.metaworld.mirror.task import (
    MirrorTask,
    ModelFacts,
    View,
    hamacher_product,
    tolerance,
)

LID_QPOS = 9  # MetaWorld's `_set_obj_xyz`: qpos[9:12] = pos, qvel[9:15] = 0
LID_Z = float(np.float32(0.02))  # init_config["obj_init_pos"][-1] (a float32 array)


class BoxClose(MirrorTask):
    name = "box-close-v3"
    xml = "sawyer_xyz/sawyer_box.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.05, 0.5, 0.02, -0.1, 0.7, 0.133)
    reset_high = (0.05, 0.55, 0.02, 0.1, 0.8, 0.133)
    goal_low = (-0.1, 0.7, 0.133)
    goal_high = (0.1, 0.8, 0.133)
    bodies = ("top_link",)
    moved_bodies = ("boxbody",)
    hand_reset_per_episode = True  # the lid falls off the moved box during it
    settle_steps = 1
    has_reward = True

    def accept(self, vec: jax.Array) -> jax.Array:
        return jnp.linalg.norm(vec[:2] - vec[3:5]) >= 0.25

    def _obj_init(self, vec: jax.Array) -> jax.Array:
        return jnp.concatenate([vec[:2], jnp.array([LID_Z])])

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        box = jnp.concatenate([vec[3:5], jnp.asarray(facts.rest["body:boxbody"][2:3])])
        qpos = qpos.at[LID_QPOS : LID_QPOS + 3].set(self._obj_init(vec))
        qvel = qvel.at[LID_QPOS : LID_QPOS + 6].set(0.0)
        return qpos, qvel, {"boxbody": box}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {"target_pos": vec[3:6], "obj_init_pos": self._obj_init(vec)}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("top_link"), view.body_quat("top_link")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) < 0.08

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: 2 x the grip effort with the hand at the lid's handle (kept above a
        funnel round it), 8 x the lid lifted (0.2) and brought onto the box (0.8, z weighted
        3); 10 on success; all times the lid's uprightness."""
        hand = obs[:3]
        lid = obs[4:7] + jnp.asarray([0.0, 0.0, 0.02], jnp.float32)
        radius = jnp.linalg.norm(hand[:2] - lid[:2])
        floor = jnp.where(
            radius <= 0.02, 0.0, 0.04 * jnp.log(jnp.maximum(radius - 0.02, 1e-30)) + 0.4
        )
        above = jnp.where(hand[2] >= floor, 1.0, tolerance(floor - hand[2], 0.01, floor / 2.0))
        ready = hamacher_product(above, tolerance(jnp.linalg.norm(hand - lid), 0.02, 0.5))
        scale = jnp.asarray([1.0, 1.0, 3.0], jnp.float32)
        placed = tolerance(jnp.linalg.norm((episode["target_pos"] - lid) * scale), 0.05, 0.25)
        lifted = 0.2 * (lid[2] > 0.04) + 0.8 * placed
        grab = (jnp.clip(action[3], -1.0, 1.0) + 1.0) / 2.0
        reward = 2.0 * hamacher_product(grab, ready) + 8.0 * lifted
        reward = jnp.where(self.success(obs, view, episode), 10.0, reward)
        ideal = jnp.asarray([0.707, 0.0, 0.0, 0.707], jnp.float32)
        return reward * jnp.maximum(1.0 - jnp.linalg.norm(obs[7:11] - ideal) / 0.2, 0.0)


TASKS = (BoxClose(),)
