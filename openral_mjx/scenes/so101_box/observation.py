"""`so101_box` observation: one flat float32 vector, named slices in `obs_layout`.

Robot joint positions and velocities, the end-effector site's position, tube and block
positions and quaternions (w, x, y, z), world frame; then any sensor observations the options
ask for, flattened row-major. Read from the physics `Quantities` only.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from openral_mjx.physics import Quantities
from openral_mjx.scenes.base import arm_obs_layout
from openral_mjx.scenes.sensor_obs import sensor_obs
from openral_mjx.scenes.so101_box.task import BLOCK, EE, TUBE

# The task's slices, after the arm's joint positions, velocities and end-effector position.
TASK_SLICES = {"tube_pos": 3, "tube_quat": 4, "block_pos": 3, "block_quat": 4}


def obs_layout(
    n_joints: int, sensor_shapes: dict[str, tuple[int, ...]]
) -> dict[str, tuple[int, int]]:
    """Named slices (start, size) of the observation of an arm with `n_joints` joints."""
    return arm_obs_layout(n_joints, TASK_SLICES, sensor_shapes)


def observe(
    q: Quantities,
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
            q.body_pos[TUBE],
            q.body_quat[TUBE],
            q.body_pos[BLOCK],
            q.body_quat[BLOCK],
            *sensor_obs(q, sensor_shapes),
        ]
    ).astype(jnp.float32)
