"""dial-turn-v3: turn the dial (MetaWorld 3.1.1).

The vector is the ``dial`` body's position (moved per episode; the knob's hinge is left as
the hand reset leaves it); the goal is the drawn position + (0, 0.03, 0.03). Observed object:
the point 0.05 m from the dial's centre at the knob's angle θ (centre + 0.05 (sin θ, -cos θ,
0)) and the ``dial`` body's ``xquat`` (w-x-y-z). Success: that point within 0.07 m of the
goal (MetaWorld reads it from the simulator, not the clipped observation).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp

from openral_mjx.benchmarks.metaworld.mirror.task import ModelFacts, MovedBodyTask, View

DIAL_RADIUS = 0.05
TARGET_RADIUS = 0.07


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

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {"target_pos": vec + jnp.array([0.0, 0.03, 0.03]), "obj_init_pos": vec}

    def _knob(self, view: View) -> jax.Array:
        angle = view.qpos("knob_Joint_1")
        offset = jnp.stack([jnp.sin(angle), -jnp.cos(angle), jnp.zeros_like(angle)])
        return view.body_pos("dial") + DIAL_RADIUS * offset

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return self._knob(view), view.body_quat("dial")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(self._knob(view) - episode["target_pos"]) <= TARGET_RADIUS


TASKS = (DialTurn(),)
