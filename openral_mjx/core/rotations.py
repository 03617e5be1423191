"""Rotations in MuJoCo's conventions (quaternions w-x-y-z, rotation matrices acting on column
vectors), in one place. The JAX functions unroll their arithmetic in a fixed order (see
`fixed_order`), so a seed's episode does not depend on the batch it runs in; `quat_to_mat_np`
is MuJoCo's own conversion, for host-side model preparation.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np


def quat_to_mat(q: jax.Array) -> jax.Array:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4), w-x-y-z (MuJoCo's order)."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def quat_axis_z(quat: jax.Array) -> jax.Array:
    """A body's local +z axis in the world frame, from its quaternion (w, x, y, z): the third
    column of `quat_to_mat`."""
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    return jnp.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])


def rotate_inverse(quat: jax.Array, v: jax.Array) -> jax.Array:
    """`v` (world) in the frame of the body with quaternion `quat` (one env): R^T v, fixed
    order."""
    r = quat_to_mat(quat)
    # R^T v: column j of R dotted with v.
    return jnp.stack([r[0, j] * v[0] + r[1, j] * v[1] + r[2, j] * v[2] for j in range(3)])


def quat_mul(a: jax.Array, b: jax.Array) -> jax.Array:
    """Hamilton products a * b of w-x-y-z quaternions (..., 4)."""
    aw, ax, ay, az = (a[..., i] for i in range(4))
    bw, bx, by, bz = (b[..., i] for i in range(4))
    return jnp.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def mat_to_quat(mat: jax.Array) -> jax.Array:
    """Rotation matrices (..., 3, 3) -> unit quaternions (..., 4), w-x-y-z with w >= 0 (MuJoCo's
    `mju_mat2Quat` convention; Shepperd's method, stable for every rotation)."""
    r = mat
    trace = r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2]
    candidates = jnp.stack(
        [
            jnp.stack(
                [
                    1 + trace,
                    r[..., 2, 1] - r[..., 1, 2],
                    r[..., 0, 2] - r[..., 2, 0],
                    r[..., 1, 0] - r[..., 0, 1],
                ],
                -1,
            ),
            jnp.stack(
                [
                    r[..., 2, 1] - r[..., 1, 2],
                    1 + r[..., 0, 0] - r[..., 1, 1] - r[..., 2, 2],
                    r[..., 0, 1] + r[..., 1, 0],
                    r[..., 0, 2] + r[..., 2, 0],
                ],
                -1,
            ),
            jnp.stack(
                [
                    r[..., 0, 2] - r[..., 2, 0],
                    r[..., 0, 1] + r[..., 1, 0],
                    1 - r[..., 0, 0] + r[..., 1, 1] - r[..., 2, 2],
                    r[..., 1, 2] + r[..., 2, 1],
                ],
                -1,
            ),
            jnp.stack(
                [
                    r[..., 1, 0] - r[..., 0, 1],
                    r[..., 0, 2] + r[..., 2, 0],
                    r[..., 1, 2] + r[..., 2, 1],
                    1 - r[..., 0, 0] - r[..., 1, 1] + r[..., 2, 2],
                ],
                -1,
            ),
        ],
        -2,
    )
    pick = jnp.argmax(jnp.stack([trace, r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]], -1), axis=-1)
    q = jnp.take_along_axis(candidates, pick[..., None, None], axis=-2)[..., 0, :]
    q = q / jnp.linalg.norm(q, axis=-1, keepdims=True)
    return jnp.where(q[..., :1] < 0, -q, q)


def quat_to_mat_np(q: np.ndarray) -> np.ndarray:
    """MuJoCo's `mju_quat2Mat` in float64: a model's quaternion as a 3x3 matrix (host side)."""
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, np.asarray(q, np.float64))
    return m.reshape(3, 3)
