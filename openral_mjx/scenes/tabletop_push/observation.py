"""`tabletop_push` observation: one flat float32 vector, named slices in `obs_layout`.

Robot joint positions and velocities, end-effector position, cube position and quaternion
(w, x, y, z), goal position (x, y), world frame (metres, radians); then any sensor observations
the options ask for, flattened row-major. Read from the physics `Quantities` and the goal.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.physics import Quantities
from openral_mjx.scenes.base import arm_obs_layout
from openral_mjx.scenes.sensor_obs import sensor_obs
from openral_mjx.scenes.tabletop_push.task import CUBE, EE

# The task's slices, after the arm's joint positions, velocities and end-effector position.
TASK_SLICES = {"cube_pos": 3, "cube_quat": 4, "goal_xy": 2}


def obs_layout(
    n_joints: int, sensor_shapes: dict[str, tuple[int, ...]]
) -> dict[str, tuple[int, int]]:
    """Named slices (start, size) of the observation of an arm with `n_joints` joints."""
    return arm_obs_layout(n_joints, TASK_SLICES, sensor_shapes)


def observe(
    q: Quantities,
    goal_xy: jax.Array,
    qpos_adr: np.ndarray,
    dof_adr: np.ndarray,
    sensor_shapes: dict[str, tuple[int, ...]],
) -> jax.Array:
    """The flat observation, in `obs_layout` order; `qpos_adr`/`dof_adr`: the robot joints'."""
    return jnp.concatenate(
        [
            q.qpos[qpos_adr],
            q.qvel[dof_adr],
            q.site_pos[EE],
            q.body_pos[CUBE],
            q.body_quat[CUBE],
            goal_xy,
            *sensor_obs(q, sensor_shapes),
        ]
    ).astype(jnp.float32)
