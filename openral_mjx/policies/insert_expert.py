"""Scripted tube inserter for `so101_box`: grasp a standing tube, carry it, align, lower it in.

A state machine on the observation (privileged object poses), with Cartesian targets turned
into joint targets by one damped least-squares step per control step (as `push_expert`):

0. approach: the grasp point to pre-grasp, jaw shut (an open jaw sweeps through things), tool
   vertical and the fingers' width direction radial. Pre-grasp is at grasp height beside the
   tube, towards the pan axis, so that the open jaws can slide around the tube sideways: a
   top-down approach would need the finger tips above the 9 cm tube, where the SO-101 cannot
   hold its tool vertical.
1. open: open the jaw at pre-grasp.
2. slide: the grasp point onto the tube's axis.
3. close: close the jaw for `close_steps` control steps.
4. lift: the tube's lower end to `carry_clearance` above the block's top face.
5. carry: the lower end over the hole's axis at that height.
6. align: hold until the lower end is within `align_tolerance` of the hole's axis.
7. insert: lower the tube along the hole's axis to the floor (slowly, correcting sideways at
   full speed).

Before the grasp the controlled point is the gripper's `grasp` site; once the tube is held it
is the tube's observed lower end, with the tube's observed axis held vertical (closed loop on
the object, so grasp offsets do not matter). If the tube leaves the grasp on the way, the
expert starts over.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from openral_mjx.core import fixed_order as fo
from openral_mjx.core.rotations import quat_axis_z
from openral_mjx.policies.base import Policy

# q -> (site position, site rotation matrix, jacp (3, n), jacr (3, n)), world frame.
SiteKinematics = Callable[[jax.Array], tuple[jax.Array, jax.Array, jax.Array, jax.Array]]

APPROACH, OPEN, SLIDE, CLOSE, LIFT, CARRY, ALIGN, INSERT = range(8)


def _limit(v: jax.Array, max_norm: float) -> jax.Array:
    """`v` scaled down to at most `max_norm` long."""
    return v * jnp.minimum(1.0, max_norm / (fo.norm(v) + 1e-9))


def insert_expert(
    layout: dict[str, tuple[int, int]],
    fk: SiteKinematics,
    actuator_joint: jax.Array,
    low: jax.Array,
    high: jax.Array,
    *,
    gripper_actuator: int,
    gripper_joint: int,
    pan_xy: tuple[float, float],
    tube_length: float,
    block_height: float,
    grasp_height: float = 0.070,
    pre_grasp_offset: float = 0.035,
    gripper_open: float = 1.0,
    gripper_closed: float = -0.17,
    close_steps: int = 15,
    carry_clearance: float = 0.006,
    align_tolerance: float = 0.0003,
    insert_depth: float = 0.023,
    max_step_m: float = 0.015,
    fine_step_m: float = 0.003,
    insert_step_m: float = 0.0004,
    orient_weight: float = 0.01,
    max_tilt_step: float = 0.05,
    damping: float = 1e-4,
    max_joint_step: float = 0.15,
) -> Policy:
    """Build the expert.

    Args:
        layout: the scene's observation slices (`joint_pos`, `tube_pos`, `tube_quat`,
            `block_pos`).
        fk: kinematics of the gripper's grasp site (where a grasped tube's axis sits),
            whose +z axis points up, out of the wrist, when the tool points down.
        actuator_joint: for each actuator, the index of its joint in `joint_pos`.
        low, high: actuator control limits.
        gripper_actuator, gripper_joint: index of the jaw's actuator, and of its joint in
            `joint_pos`.
        pan_xy: where the arm's vertical pan axis meets the floor (world x, y).
        tube_length, block_height: object sizes (m).
        grasp_height: height of the grasp point above the tube's lower end (m).
        insert_depth: how far below the block's top face to drive the lower end (m).
    """

    def part(obs: jax.Array, name: str) -> jax.Array:
        start, size = layout[name]
        return obs[start : start + size]

    up = jnp.array([0.0, 0.0, 1.0])
    pan_xy = jnp.asarray(pan_xy, jnp.float32)

    def init(key, obs_spec):
        del key, obs_spec
        return None, (jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32))

    def next_phase(
        phase, timer, pos, rot, q, pre, grasp_point, side, lower, hole_xy, carry_z, held
    ):
        """The state machine's transitions at this observation (see the module docstring)."""
        tool, y_axis = rot[:, 2], rot[:, 1]
        y_goal = jnp.where(fo.dot(y_axis, side) >= 0, side, -side)
        aligned = (fo.norm(tool - up) < 0.05) & (fo.norm(y_goal - y_axis) < 0.05)
        jaw_open = q[gripper_joint] > 0.9 * gripper_open
        lower_err_xy = fo.norm(lower[:2] - hole_xy)
        near_pre = (fo.norm(pos[:2] - pre[:2]) < 0.003) & (jnp.abs(pos[2] - pre[2]) < 0.005)
        steps = [
            (APPROACH, near_pre & aligned),
            (OPEN, (fo.norm(pos - pre) < 0.002) & aligned & jaw_open),
            (SLIDE, fo.norm(pos - grasp_point) < 0.002),
        ]
        for p, cond in steps:
            phase = jnp.where((phase == p) & cond, p + 1, phase)
        timer = jnp.where(phase == CLOSE, timer + 1, 0)
        steps = [
            (CLOSE, timer > close_steps),
            (LIFT, lower[2] > carry_z - 0.002),
            (CARRY, lower_err_xy < 0.002),
            (ALIGN, lower_err_xy < align_tolerance),
        ]
        for p, cond in steps:
            phase = jnp.where((phase == p) & cond, p + 1, phase)
        phase = jnp.where((phase >= LIFT) & ~held, APPROACH, phase)
        return phase, timer, y_goal

    def position_error(phase, pos, pre, grasp_point, lower, hole_xy, carry_z, top_z):
        """The controlled point (the grasp site, or the held tube's lower end from the lift
        on) and its step towards the phase's target, limited per phase."""

        def over_hole(z):
            return jnp.append(hole_xy, z)

        targets = jnp.stack(
            [
                pre,
                pre,
                grasp_point,
                grasp_point,
                jnp.append(lower[:2], carry_z),
                over_hole(carry_z),
                over_hole(carry_z),
                over_hole(top_z - insert_depth),
            ]
        )
        fine, ins = fine_step_m, insert_step_m
        step_limit = jnp.array([max_step_m, fine, fine, fine, fine, fine, fine, ins])[phase]
        point = jnp.where(phase >= LIFT, lower, pos)
        raw = targets[phase] - point
        # Inserting, the descent is slow but the sideways correction is not slowed with it.
        err = jnp.where(
            phase == INSERT,
            jnp.append(_limit(raw[:2], fine_step_m), jnp.clip(raw[2], -ins, ins)),
            _limit(raw, step_limit),
        )
        return point, err

    def joint_step(phase, pos, rot, jp, jr, point, err, axis, y_goal, n):
        """One damped least-squares step: the point's error, the axis held vertical and,
        before the grasp, the roll, weighted; clipped per joint."""
        tool, y_axis = rot[:, 2], rot[:, 1]
        # Jacobians of the controlled point and axis (a point rigidly attached to the gripper).
        r = point - pos
        cur_axis = jnp.where(phase >= LIFT, axis, tool)
        jpt = jnp.stack([jp[:, i] + fo.cross(jr[:, i], r) for i in range(n)], 1)
        jax_ = jnp.stack([fo.cross(jr[:, i], cur_axis) for i in range(n)], 1)
        axis_err = _limit(up - cur_axis, max_tilt_step)
        # Roll: the grasp site's y axis along the radial line (either sign), horizontal; only
        # before the grasp (a 5-joint arm cannot also hold the roll while it places the tube's
        # end and axis).
        jy = jnp.stack([fo.cross(jr[:, i], y_axis) for i in range(n)], 1)
        jy = jnp.where(phase < CLOSE, jy, 0.0)
        y_err = _limit(jnp.where(phase < CLOSE, y_goal - y_axis, 0.0), max_tilt_step)
        a = (
            fo.matmul(jpt.T, jpt)
            + orient_weight * (fo.matmul(jax_.T, jax_) + fo.matmul(jy.T, jy))
            + damping * jnp.eye(n)
        )
        b = fo.matmul(jpt.T, err) + orient_weight * (
            fo.matmul(jax_.T, axis_err) + fo.matmul(jy.T, y_err)
        )
        return jnp.clip(fo.solve_spd(a, b), -max_joint_step, max_joint_step)

    def act(params, pstate, obs, key):
        del params, key
        phase, timer = pstate
        q = part(obs, "joint_pos")
        tube, block = part(obs, "tube_pos"), part(obs, "block_pos")
        axis = quat_axis_z(part(obs, "tube_quat"))
        axis = jnp.where(axis[2] < 0, -axis, axis)  # the tube is symmetric: take the upper end
        lower = tube - axis * (tube_length / 2)
        hole_xy, top_z = block[:2], block[2] + block_height / 2

        pos, rot, jp, jr = fk(q)
        # The jaws' free side (the fingers' width, grasp-site y) is held radial, so the open
        # jaws reach the tube from the pan axis' side.
        radial = tube[:2] - pan_xy
        side = jnp.append(-radial / jnp.maximum(fo.norm(radial), 1e-6), 0.0)
        grasp_point = lower + axis * grasp_height
        rel = pos - tube
        off_axis = fo.norm(rel - axis * fo.dot(rel, axis))
        held = (off_axis < 0.008) & (
            jnp.abs(fo.dot(rel, axis) - (grasp_height - tube_length / 2)) < 0.02
        )
        pre = grasp_point + side * pre_grasp_offset
        carry_z = top_z + carry_clearance
        phase, timer, y_goal = next_phase(
            phase, timer, pos, rot, q, pre, grasp_point, side, lower, hole_xy, carry_z, held
        )
        point, err = position_error(phase, pos, pre, grasp_point, lower, hole_xy, carry_z, top_z)
        dq = joint_step(phase, pos, rot, jp, jr, point, err, axis, y_goal, q.shape[0])
        action = (q + dq)[actuator_joint]
        grip = jnp.array([0.0, gripper_open, gripper_open, *[gripper_closed] * 5])[phase]
        action = action.at[gripper_actuator].set(grip)
        return jnp.clip(action, low, high), (phase, timer)

    return Policy("scripted", init, act, cache_key="scripted")
