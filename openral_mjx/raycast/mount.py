"""Where a sensor sits: a body, site or camera frame, resolved by name at build time."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.rotations import quat_to_mat
from openral_mjx.raycast.geoms import is_static, mat_mat, mat_vec, rest_data


@dataclasses.dataclass(frozen=True)
class Mount:
    """A frame rigidly attached to `body` at offset (`pos`, `rot`) in the body's frame.

    A frame on a static body has `body` 0 and its world pose as the offset.
    """

    body: int
    pos: np.ndarray  # (3,)
    rot: np.ndarray  # (3, 3)
    root: int  # the top-level body (child of the world) the frame hangs from; 0 for the world

    @property
    def static(self) -> bool:
        return self.body == 0

    def pose(self, xpos: jax.Array, xquat: jax.Array) -> tuple[jax.Array, jax.Array]:
        """World position (3,) and rotation (3, 3) from body poses indexed by body id."""
        if self.static:
            return jnp.asarray(self.pos), jnp.asarray(self.rot)
        rot_b = quat_to_mat(xquat[self.body])
        return xpos[self.body] + mat_vec(rot_b, jnp.asarray(self.pos)), mat_mat(
            rot_b, jnp.asarray(self.rot)
        )


# A camera's pose in its body's frame (MuJoCo's `cam_pos` (3,), `cam_quat` (4,) w-x-y-z).
CameraLocal = tuple[jax.Array, jax.Array]
# How far a randomised camera may move from its model pose: the ray caster's view culling of
# static geoms keeps this much margin.
JITTER_POS_M = 0.02
JITTER_ROT_RAD = 0.05


def moved(
    pos: jax.Array, rot: jax.Array, nominal: tuple[np.ndarray, np.ndarray], local: CameraLocal
) -> tuple[jax.Array, jax.Array]:
    """A frame's world pose (`pos`, `rot`) with its body-frame pose changed from `nominal` to
    `local`: the same change, expressed in the frame itself, applied to the world pose (so it
    holds for frames on static and moving bodies alike)."""
    p0, q0 = nominal
    r0 = np.zeros(9)
    mujoco.mju_quat2Mat(r0, np.asarray(q0, np.float64))
    r0t = jnp.asarray(r0.reshape(3, 3).T, jnp.float32)
    p1, q1 = local
    q1 = q1 / jnp.linalg.norm(q1)
    delta_p = mat_vec(r0t, p1 - jnp.asarray(p0, jnp.float32))
    delta_r = mat_mat(r0t, quat_to_mat(q1))
    return pos + mat_vec(rot, delta_p), mat_mat(rot, delta_r)


def _mount(model, data, body: int, pos, quat, world_pos, world_mat) -> Mount:
    root = int(model.body_rootid[body])
    if is_static(model, body):
        return Mount(
            0,
            np.asarray(world_pos, np.float32),
            np.asarray(world_mat, np.float32).reshape(3, 3),
            root,
        )
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.asarray(quat, np.float64))
    return Mount(body, np.asarray(pos, np.float32), rot.reshape(3, 3).astype(np.float32), root)


def body_or_site(model: mujoco.MjModel, name: str, what: str) -> Mount:
    """The frame of the body or site `name` (a site wins over a body of the same name)."""
    data = rest_data(model)
    s = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
    if s >= 0:
        b = int(model.site_bodyid[s])
        return _mount(
            model,
            data,
            b,
            model.site_pos[s],
            model.site_quat[s],
            data.site_xpos[s],
            data.site_xmat[s],
        )
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    if b >= 0:
        return _mount(
            model, data, b, np.zeros(3), np.array([1.0, 0, 0, 0]), data.xpos[b], data.xmat[b]
        )
    bodies = [model.body(i).name for i in range(model.nbody)]
    sites = [model.site(i).name for i in range(model.nsite)]
    raise ConfigError(
        f"{what}: no body or site named {name!r}; bodies: {', '.join(bodies)}; "
        f"sites: {', '.join(sites) or '(none)'}"
    )


def camera(model: mujoco.MjModel, name: str, what: str) -> tuple[int, Mount]:
    """The id and frame of MJCF camera `name` (MuJoCo's: looks along -z, +y up).

    Only cameras fixed to their body (mode `fixed`) and perspective are supported.
    """
    c = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name)
    if c < 0:
        cams = [model.camera(i).name for i in range(model.ncam)]
        raise ConfigError(f"{what}: unknown camera {name!r}; valid: {', '.join(cams) or '(none)'}")
    if int(model.cam_mode[c]) != int(mujoco.mjtCamLight.mjCAMLIGHT_FIXED):
        raise ConfigError(f"{what}: camera {name!r} must have mode 'fixed' to be ray cast")
    if int(model.cam_projection[c]) != int(mujoco.mjtProjection.mjPROJ_PERSPECTIVE):
        raise ConfigError(f"{what}: camera {name!r} must be a perspective camera")
    data = rest_data(model)
    b = int(model.cam_bodyid[c])
    return c, _mount(
        model, data, b, model.cam_pos[c], model.cam_quat[c], data.cam_xpos[c], data.cam_xmat[c]
    )
