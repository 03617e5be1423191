"""dial-turn-v3: turn the dial (MetaWorld 3.1.1).

The vector is the ``dial`` body's position (moved per episode; the knob's hinge is left as
the hand reset leaves it); the goal is the drawn position + (0, 0.03, 0.03). Observed object:
the point 0.05 m from the dial's centre at the knob's angle θ (centre + 0.05 (sin θ, -cos θ,
0)) and the ``dial`` body's ``xquat`` (w-x-y-z). Success: that point within 0.07 m of the
goal (MetaWorld reads it from the simulator, not the clipped observation). Reward: MetaWorld's
v2, the tcp at a push point beside the knob with the grip closed, times the knob's approach.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import (
    ModelFacts,
    MovedBodyTask,
    View,
    hamacher_product,
    tolerance,
)

DIAL_RADIUS = 0.05
TARGET_RADIUS = 0.07
PUSH_OFFSET = (0.05, 0.02, 0.09)  # MetaWorld's push point, from the knob


class DialTurn(MovedBodyTask):
    name = "dial-turn-v3"
    xml = "sawyer_xyz/sawyer_dial.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.7, 0.0)
    reset_high = (0.1, 0.8, 0.0)
    goal_low = (-0.1, 0.73, 0.0299)
    goal_high = (0.1, 0.83, 0.0301)
    bodies = ("dial",)
    moved_bodies = ("dial",)
    has_reward = True

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {
            "target_pos": vec + jnp.array([0.0, 0.03, 0.03]),
            "obj_init_pos": vec,
            "push_init": self._knob(view) + jnp.asarray(PUSH_OFFSET, jnp.float32),
        }

    def _knob(self, view: View) -> jax.Array:
        angle = view.qpos("knob_Joint_1")
        offset = jnp.stack([jnp.sin(angle), -jnp.cos(angle), jnp.zeros_like(angle)])
        return view.body_pos("dial") + DIAL_RADIUS * offset

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return self._knob(view), view.body_quat("dial")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(self._knob(view) - episode["target_pos"]) <= TARGET_RADIUS

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """MetaWorld's v2: 10 x (the tcp at the push point with the grip closed) x (the knob
        at the goal)."""
        knob, target, push_init = self._knob(view), episode["target_pos"], episode["push_init"]
        init_margin = jnp.abs(jnp.linalg.norm(push_init - target) - TARGET_RADIUS)
        in_place = tolerance(jnp.linalg.norm(knob - target), TARGET_RADIUS, init_margin)
        push = knob + jnp.asarray(PUSH_OFFSET, jnp.float32)
        reach_margin = jnp.abs(jnp.linalg.norm(push_init - episode["init_tcp"]) - 0.005)
        reach = tolerance(jnp.linalg.norm(push - view.tcp_center), 0.005, reach_margin, "gaussian")
        reach = hamacher_product(reach, jnp.clip(action[-1], 0.0, 1.0))
        return 10.0 * hamacher_product(reach, in_place)


TASKS = (DialTurn(),)
