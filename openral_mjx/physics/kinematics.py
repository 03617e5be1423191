"""Forward kinematics of a robot's joint chain in plain JAX, read off a compiled `MjModel`.

`mjx.kinematics` evaluates every body of the scene and costs milliseconds per call on a CPU
under `vmap`+`jacfwd`; a scripted controller needs only the chain from the root to one site.
This unrolls that chain at trace time (hinge and slide joints, MuJoCo's conventions: a body's
frame is its parent's composed with `body_pos`/`body_quat`, then rotated about each hinge's
anchor `jnt_pos` and axis `jnt_axis` by `q - qpos0`, or translated along a slide's axis).
Tests hold it to MuJoCo C's `site_xpos`/`site_xmat`.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core import fixed_order as fo
from openral_mjx.core.rotations import quat_to_mat_np


def _axis_angle(axis: np.ndarray, angle: jax.Array) -> jax.Array:
    """Rotation matrix about unit `axis` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + jnp.sin(angle) * k + (1 - jnp.cos(angle)) * (k @ k)


def _mm(a: jax.Array, b: jax.Array) -> jax.Array:
    """3x3 @ 3x3 (or 3x3 @ 3) as explicit sums of products in a fixed order.

    XLA's CPU reductions pick their summation order by batch shape, which changes the last bit
    of a vmapped matmul with the batch size; fixed-order elementwise arithmetic does not, so a
    seed's episode stays bit-identical at any batch size.
    """
    if b.ndim == 1:
        return a[:, 0] * b[0] + a[:, 1] * b[1] + a[:, 2] * b[2]
    return a[:, 0:1] * b[0:1, :] + a[:, 1:2] * b[1:2, :] + a[:, 2:3] * b[2:3, :]


def site_kinematics(
    model: mujoco.MjModel, site: int, qpos_adr: np.ndarray
) -> Callable[[jax.Array], tuple[jax.Array, jax.Array, jax.Array, jax.Array]]:
    """Return `fk(q) -> (site position, site rotation matrix, jacp, jacr)`, world frame.

    `q` holds the positions of the joints at `qpos_adr` (hinge/slide); every other joint on the
    chain stays at `qpos0`. `jacp`/`jacr` (3, len(q)) are the site's translational and
    rotational Jacobians (MuJoCo's `mj_jacSite`), built geometrically from each joint's world
    axis and anchor: one forward pass, no autodiff. Joints off the chain get zero columns.
    """
    chain: list[int] = []
    b = int(model.site_bodyid[site])
    while b != 0:
        chain.append(b)
        b = int(model.body_parentid[b])
    chain.reverse()
    index = {int(a): i for i, a in enumerate(qpos_adr)}
    steps = []
    for b in chain:
        joints = []
        for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
            adr = int(model.jnt_qposadr[j])
            jtype = int(model.jnt_type[j])
            if jtype not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
                raise ValueError(f"joint {model.joint(j).name!r}: only hinge/slide supported")
            joints.append(
                (
                    jtype,
                    index.get(adr),
                    float(model.qpos0[adr]),
                    np.array(model.jnt_pos[j]),
                    np.array(model.jnt_axis[j]),
                )
            )
        steps.append((np.array(model.body_pos[b]), quat_to_mat_np(model.body_quat[b]), joints))
    site_pos = np.array(model.site_pos[site])
    site_rot = quat_to_mat_np(model.site_quat[site])
    hinge = int(mujoco.mjtJoint.mjJNT_HINGE)

    def fk(q: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
        pos, rot = jnp.zeros(3, q.dtype), jnp.eye(3, dtype=q.dtype)
        axes: dict[int, tuple[int, jax.Array, jax.Array]] = {}  # i -> (type, axis, anchor)
        for body_pos, body_rot, joints in steps:
            pos = pos + _mm(rot, jnp.asarray(body_pos, q.dtype))
            rot = _mm(rot, jnp.asarray(body_rot, q.dtype))
            for jtype, i, q0, anchor, axis in joints:
                if i is None:
                    continue
                anchor = jnp.asarray(anchor, q.dtype)
                world_axis = _mm(rot, jnp.asarray(axis, q.dtype))
                if jtype == hinge:
                    new_rot = _mm(rot, _axis_angle(axis, q[i] - q0).astype(q.dtype))
                    axes[i] = (jtype, world_axis, pos + _mm(rot, anchor))
                    pos = pos + _mm(rot, anchor) - _mm(new_rot, anchor)
                    rot = new_rot
                else:
                    axes[i] = (jtype, world_axis, pos)
                    pos = pos + world_axis * (q[i] - q0)
        site_p = pos + _mm(rot, jnp.asarray(site_pos, q.dtype))
        zero = jnp.zeros(3, q.dtype)
        jacp, jacr = [], []
        for i in range(q.shape[0]):
            jtype, w, anchor = axes.get(i, (hinge, zero, site_p))
            jacp.append(fo.cross(w, site_p - anchor) if jtype == hinge else w)
            jacr.append(w if jtype == hinge else zero)
        site_r = _mm(rot, jnp.asarray(site_rot, q.dtype))
        return site_p, site_r, jnp.stack(jacp, axis=1), jnp.stack(jacr, axis=1)

    return fk
