"""sweep-v3, sweep-into-v3: sweep the puck off the table's edge or into a hole (MetaWorld 3.1.1).

sweep draws the puck's xyz only; its free joint goes to the drawn xy at z 0.02 (velocities
zeroed) and the goal is (0.5, drawn y, 0.01). Observed object: the ``obj`` body's position and
quaternion as MuJoCo's (w-x-y-z). Success: the observed puck within 0.05 of the goal.

sweep-into draws (puck xyz, goal xyz) but keeps the fixed goal (0, 0.84, 0.02), redrawing while
the puck's xy is closer than 0.15 to it; the puck goes to the drawn xy at the ``obj`` body's
rest height. Observed object: the ``obj`` body's position and the ``objGeom`` geom's orientation
as scipy's quaternion. Success: the observed puck within 0.05 of the goal in xy.
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
    hamacher_product,
    matrix_quat,
    pushing_caging,
    tolerance,
)

FREE_QPOS, FREE_DOF = 9, 9  # MetaWorld's `_set_obj_xyz` writes qpos[9:12], qvel[9:15]
SWEEP_GOAL = (0.5, 0.65, 0.01)
SWEEP_PUCK_Z = 0.02  # init_config["obj_init_pos"][-1]
SWEEP_INTO_GOAL = (0.0, 0.84, 0.02)


def _swept(
    view: View,
    episode: Mapping[str, Any],
    obj: jax.Array,
    target: jax.Array,
    grip_margin: float,
    xz_thresh: float,
) -> jax.Array:
    """MetaWorld's v2 for both: 2 x the puck caged (its own caging, radius 0.02) + 6 x that
    times the puck's approach to `target`; 10 within 0.05."""
    to_target = jnp.linalg.norm(obj - target)
    in_place = tolerance(to_target, 0.05, jnp.linalg.norm(episode["obj_init_pos"] - target))
    caged = pushing_caging(view, episode, obj, 0.02, grip_margin, xz_thresh)
    reward = 2.0 * caged + 6.0 * hamacher_product(caged, in_place)
    return jnp.where(to_target < 0.05, 10.0, reward)


def _set_free(qpos: jax.Array, qvel: jax.Array, pos: jax.Array) -> tuple[jax.Array, jax.Array]:
    return qpos.at[FREE_QPOS : FREE_QPOS + 3].set(pos), qvel.at[FREE_DOF : FREE_DOF + 6].set(0.0)


class Sweep(MirrorTask):
    name = "sweep-v3"
    xml = "sawyer_xyz/sawyer_sweep_v3.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.6, 0.02)
    reset_high = (0.1, 0.7, 0.02)
    goal_low = (0.49, 0.6, 0.0)
    goal_high = (0.51, 0.7, 0.02)
    bodies = ("obj", "leftpad", "rightpad")
    has_reward = True

    def _obj_init(self, vec: jax.Array) -> jax.Array:
        return jnp.concatenate([vec[:2], jnp.full((1,), SWEEP_PUCK_Z, vec.dtype)])

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos, qvel = _set_free(qpos, qvel, self._obj_init(vec))
        return qpos, qvel, {}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        target = jnp.asarray(SWEEP_GOAL, vec.dtype).at[1].set(vec[1])
        return {"target_pos": target, "obj_init_pos": self._obj_init(vec)}

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("obj"), view.body_quat("obj")

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        return jnp.linalg.norm(obs[4:7] - episode["target_pos"]) <= 0.05

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """See `_swept`: the goal as drawn."""
        return _swept(view, episode, obs[4:7], episode["target_pos"], 0.01, 0.005)


class SweepInto(MirrorTask):
    name = "sweep-into-v3"
    xml = "sawyer_xyz/sawyer_table_with_hole.xml"
    hand_init_pos = (0.0, 0.6, 0.2)
    reset_low = (-0.1, 0.6, 0.02, -0.001, 0.8399, 0.0199)
    reset_high = (0.1, 0.7, 0.02, 0.001, 0.8401, 0.0201)
    goal_low = (-0.001, 0.8399, 0.0199)
    goal_high = (0.001, 0.8401, 0.0201)
    bodies = ("obj", "leftpad", "rightpad")
    geoms = ("objGeom",)
    has_reward = True

    def accept(self, vec: jax.Array) -> jax.Array:
        return jnp.linalg.norm(vec[:2] - jnp.asarray(SWEEP_INTO_GOAL[:2])) >= 0.15

    def _obj_init(self, facts: ModelFacts, vec: jax.Array) -> jax.Array:
        return jnp.concatenate([vec[:2], jnp.asarray(facts.rest["body:obj"][2:3], vec.dtype)])

    def place(
        self, facts: ModelFacts, vec: jax.Array, qpos: jax.Array, qvel: jax.Array
    ) -> tuple[jax.Array, jax.Array, dict[str, jax.Array]]:
        qpos, qvel = _set_free(qpos, qvel, self._obj_init(facts, vec))
        return qpos, qvel, {}

    def episode(self, facts: ModelFacts, vec: jax.Array, view: View) -> dict[str, jax.Array]:
        return {
            "target_pos": jnp.asarray(SWEEP_INTO_GOAL, vec.dtype),
            "obj_init_pos": self._obj_init(facts, vec),
        }

    def objects(self, view: View) -> tuple[jax.Array, jax.Array]:
        return view.body_pos("obj"), matrix_quat(view.geom_quat("objGeom"))

    def success(self, obs: jax.Array, view: View, episode: Mapping[str, Any]) -> jax.Array:
        obj = obs[4:7]
        target = episode["target_pos"]
        return jnp.linalg.norm(obj[:2] - target[:2]) <= 0.05

    def reward(
        self, obs: jax.Array, view: View, episode: Mapping[str, Any], action: jax.Array
    ) -> jax.Array:
        """See `_swept`: the goal at the puck's height."""
        obj = obs[4:7]
        target = episode["target_pos"].at[2].set(obj[2])
        return _swept(view, episode, obj, target, 0.005, 0.01)


TASKS = (Sweep(), SweepInto())
