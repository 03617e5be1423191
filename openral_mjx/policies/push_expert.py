"""Scripted push expert for any arm with an end-effector site (differential IK on `jax` FK).

A three-phase state machine on the observation: (0) go above a pre-push point behind the cube
on the cube->goal line, (1) descend to push height, (2) push the cube along the line, keeping
the tool just behind it; re-approach when the tool slips sideways off the cube or passes it;
(3) stop once the cube is on the goal. Cartesian targets become joint targets by one damped
least-squares step per control step, with a secondary task keeping the tool pointing down.
The scene gives the tool's radius and the push and hover heights it measured on the robot;
actuators that drive no arm joint (a gripper's tendon) are held at a fixed ctrl, and a slow
servo's target leads its joint by more than one IK step (`lead`).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from openral_mjx.core import fixed_order as fo
from openral_mjx.policies.base import Policy

# The IK step (scenes measure an arm's reach with the same): Cartesian step limit (m),
# weight of the tool-axis-down task, damping; and the tool-to-cube-face gap before descending.
MAX_STEP_M = 0.02
ORIENT_WEIGHT = 0.001
DAMPING = 1e-4
STANDOFF_GAP_M = 0.008

# q -> (ee position, tool axis, d position / dq (3, n), d axis / dq (3, n))
ForwardKinematics = Callable[[jax.Array], tuple[jax.Array, jax.Array, jax.Array, jax.Array]]


def push_expert(
    layout: dict[str, tuple[int, int]],
    fk: ForwardKinematics,
    actuator_joint: jax.Array,
    low: jax.Array,
    high: jax.Array,
    *,
    table_z: float,
    cube_half: float,
    goal_radius: float,
    tool_radius: float = 0.01,
    push_z: float | None = None,
    hover_z: float | None = None,
    held: tuple[jax.Array, jax.Array] | None = None,
    lead: jax.Array | None = None,
    max_step_m: float = MAX_STEP_M,
    push_step_m: float = 0.005,
    push_lead_m: float = 0.01,
    orient_weight: float = ORIENT_WEIGHT,
    damping: float = DAMPING,
) -> Policy:
    """Build the expert.

    Args:
        layout: the scene's observation slices (`joint_pos`, `ee_pos`, `cube_pos`, `goal_xy`).
        fk: robot joint positions -> (end-effector position, tool axis, and their Jacobians),
            world frame.
        actuator_joint: for each actuator, the index of its joint in `joint_pos`.
        low, high: actuator control limits.
        tool_radius: how far the tool reaches sideways from the end-effector site (m).
        push_z, hover_z: heights of the site while pushing and while moving over the cube
            (world z, m); default 0.9 of the cube's half edge above the table, and 4 cm above
            the cube.
        held: (mask, ctrl) per actuator: those in `mask` get `ctrl` (actuators that drive no
            joint of the arm), the others their joint's IK target.
        lead: per actuator, how many times the IK step the target leads the joint by (>= 1):
            a servo whose velocity gain is large against its position gain (kv/kp longer than
            the control period) moves only a fraction of a step per period.
    """

    def part(obs: jax.Array, name: str) -> jax.Array:
        start, size = layout[name]
        return obs[start : start + size]

    hover_z = table_z + 2 * cube_half + 0.04 if hover_z is None else hover_z
    push_z = table_z + 0.9 * cube_half if push_z is None else push_z
    standoff = cube_half + tool_radius + STANDOFF_GAP_M

    def init(key, obs_spec):
        del key, obs_spec
        return None, jnp.zeros((), jnp.int32)

    def act(params, phase, obs, key):
        del params, key
        q, ee = part(obs, "joint_pos"), part(obs, "ee_pos")
        cube, goal = part(obs, "cube_pos")[:2], part(obs, "goal_xy")
        to_goal = goal - cube
        dist = fo.norm(to_goal)
        d = to_goal / jnp.maximum(dist, 1e-6)
        pre = cube - d * standoff
        rel = ee[:2] - cube
        along = fo.dot(rel, d)
        lateral = d[0] * rel[1] - d[1] * rel[0]
        near_pre = fo.norm(ee[:2] - pre) < 0.01

        phase = jnp.where((phase == 0) & near_pre, 1, phase)
        phase = jnp.where((phase == 1) & (ee[2] - push_z < 0.008), 2, phase)
        lost = (jnp.abs(lateral) > 0.012) | (along > -cube_half)
        phase = jnp.where((phase == 2) & lost, 0, phase)
        phase = jnp.where((phase == 2) & (dist < 0.4 * goal_radius), 3, phase)
        phase = jnp.where((phase == 3) & (dist > 0.9 * goal_radius), 0, phase)

        high_first = ee[2] < hover_z - 0.01
        approach = jnp.where(
            high_first & ~near_pre, jnp.append(ee[:2], hover_z), jnp.append(pre, hover_z)
        )
        targets = jnp.stack(
            [
                approach,
                jnp.append(pre, push_z),
                jnp.append(
                    cube - d * (cube_half + tool_radius - jnp.minimum(push_lead_m, dist)), push_z
                ),
                jnp.append(ee[:2] - d * 0.002, ee[2]),
            ]
        )
        target = targets[phase]

        pos, axis, jp, ja = fk(q)
        err = target - pos
        limit = jnp.where(phase >= 2, push_step_m, max_step_m)
        err = err * jnp.minimum(1.0, limit / (fo.norm(err) + 1e-9))
        axis_err = jnp.array([0.0, 0.0, -1.0]) - axis
        a = (
            fo.matmul(jp.T, jp)
            + orient_weight * fo.matmul(ja.T, ja)
            + damping * jnp.eye(q.shape[0])
        )
        dq = fo.solve_spd(a, fo.matmul(jp.T, err) + orient_weight * fo.matmul(ja.T, axis_err))
        if lead is None:
            action = (q + dq)[actuator_joint]
        else:
            action = q[actuator_joint] + lead * dq[actuator_joint]
        if held is not None:
            action = jnp.where(held[0], held[1], action)
        return jnp.clip(action, low, high), phase

    return Policy("scripted", init, act, cache_key="scripted")
