"""MJCF composition helpers shared by scenes: loading a robot into an `MjSpec`, orientations."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.robots import RobotSpec

Vec3 = tuple[float, float, float]


def look_at_quat(pos: Vec3, target: Vec3) -> np.ndarray:
    """Quaternion of a MuJoCo camera (looks along -z, +y up) at `pos` looking at `target`.

    The image's up direction is the world +z projected onto the image plane, or world +x when
    looking (nearly) straight down or up.
    """
    f = np.asarray(target, float) - np.asarray(pos, float)
    f /= np.linalg.norm(f)
    up = np.array([0.0, 0.0, 1.0]) if abs(f[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
    right = np.cross(f, up)
    right /= np.linalg.norm(right)
    cam_up = np.cross(right, f)
    mat = np.stack([right, cam_up, -f], axis=1)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, mat.reshape(-1))
    return quat


def yaw_quat(yaw: jax.Array) -> jax.Array:
    """Quaternion (w, x, y, z) of a rotation by `yaw` radians about world +z."""
    return jnp.stack([jnp.cos(yaw / 2), 0.0 * yaw, 0.0 * yaw, jnp.sin(yaw / 2)])


def load_robot(robot: RobotSpec) -> mujoco.MjSpec:
    """The robot's MJCF as an `MjSpec`, checked for what scenes rely on.

    Raises `ConfigError` if it does not compile, has no actuators, lacks the end-effector site,
    has joints other than hinge/slide, or actuators that do not drive a joint.
    """
    try:
        spec = mujoco.MjSpec.from_file(str(robot.mjcf_path))
        model = spec.compile()
    except Exception as e:  # mujoco raises ValueError with the XML error
        raise ConfigError(f"robot MJCF {str(robot.mjcf_path)!r} failed to load: {e}") from None
    if model.nu == 0:
        raise ConfigError(f"robot MJCF {str(robot.mjcf_path)!r} has no actuators")
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, robot.ee_site) < 0:
        sites = [model.site(i).name for i in range(model.nsite)]
        raise ConfigError(
            f"end-effector site {robot.ee_site!r} not in {robot.name}; valid: {', '.join(sites)}"
        )
    bad = [
        model.joint(i).name
        for i in range(model.njnt)
        if int(model.jnt_type[i])
        not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    ]
    if bad:
        raise ConfigError(f"robot joints must be hinge or slide; {bad} are not")
    if any(int(t) != int(mujoco.mjtTrn.mjTRN_JOINT) for t in model.actuator_trntype):
        raise ConfigError("every robot actuator must drive a joint (position actuators)")
    return spec
