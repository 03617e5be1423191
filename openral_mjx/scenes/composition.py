"""MJCF composition helpers shared by scenes: loading a robot into an `MjSpec`, checking its
actuators, its initial pose, orientations."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

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
    has joints other than hinge/slide, or actuators that are not position servos (see
    `check_servos`).
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
    check_servos(model, robot.name)
    return spec


_JOINT, _TENDON = int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_TENDON)
_SERVO_NEEDS = (
    "position servos: <position>, or <general> with gaintype fixed, biastype affine and "
    "biasprm[1] = -gainprm[0]"
)


def _servo_kind(model: mujoco.MjModel, i: int) -> str | None:
    """None if actuator `i` is a position servo (see `check_servos`), else what it is."""
    gain, bias = model.actuator_gainprm[i], model.actuator_biasprm[i]
    gaintype, biastype = int(model.actuator_gaintype[i]), int(model.actuator_biastype[i])
    dyntype = int(model.actuator_dyntype[i])
    trn = int(model.actuator_trntype[i])
    if trn not in (_JOINT, _TENDON):
        return f"driving a {mujoco.mjtTrn(trn).name[7:].lower()}, not a joint or tendon"
    if biastype == int(mujoco.mjtBias.mjBIAS_NONE):
        return "a motor (ctrl is a force or torque)"
    if dyntype == int(mujoco.mjtDyn.mjDYN_INTEGRATOR):
        return "an integrated-velocity servo (ctrl is a velocity)"
    affine = gaintype == int(mujoco.mjtGain.mjGAIN_FIXED) and biastype == int(
        mujoco.mjtBias.mjBIAS_AFFINE
    )
    filtered = dyntype in (
        int(mujoco.mjtDyn.mjDYN_NONE),
        int(mujoco.mjtDyn.mjDYN_FILTER),
        int(mujoco.mjtDyn.mjDYN_FILTEREXACT),
    )
    if affine and filtered and bias[1] == 0 and bias[2] < 0:
        return "a velocity servo (ctrl is a velocity)"
    if not (affine and filtered and gain[0] > 0 and bias[1] < 0):
        return (
            f"not a position servo (gaintype {mujoco.mjtGain(gaintype).name[8:].lower()}, "
            f"biastype {mujoco.mjtBias(biastype).name[8:].lower()})"
        )
    if trn == _TENDON:  # a held actuator: any ctrl scale will do (see `held_ctrl`)
        return None
    if not math.isclose(bias[1], -gain[0], rel_tol=1e-6):
        return f"a position servo with biasprm[1]={bias[1]:g} != -gainprm[0]={-gain[0]:g}"
    if bias[0] != 0 or model.actuator_gear[i, 0] != 1:
        return "a position servo with an offset (biasprm[0] != 0) or a gear != 1"
    return None


def check_servos(model: mujoco.MjModel, robot: str) -> None:
    """Raise `ConfigError` unless every actuator is a position servo.

    A joint's servo must hold its joint at ctrl: gaintype fixed, biastype affine, biasprm[1] =
    -gainprm[0] (as `<position>` compiles), no offset, gear 1, no integrator. A tendon's (a
    gripper's) may scale ctrl (e.g. 0-255); scenes hold it at a fixed ctrl. Motors, velocity
    servos and anything else are refused: a scene sends joint angles as ctrl.
    """
    bad = [(model.actuator(i).name or f"#{i}", _servo_kind(model, i)) for i in range(model.nu)]
    bad = [(name, kind) for name, kind in bad if kind is not None]
    if bad:
        listed = "; ".join(f"actuator {name!r} is {kind}" for name, kind in bad)
        raise ConfigError(f"{robot}: {listed}; scenes drive robots through {_SERVO_NEEDS}")


@dataclasses.dataclass(frozen=True)
class InitialPose:
    """Where a robot starts: joint positions by name and, from a keyframe, actuator ctrl."""

    qpos: dict[str, float]
    ctrl: np.ndarray | None
    source: str  # e.g. "keyframe 'home'", "qpos0"


def initial_pose(model: mujoco.MjModel, robot: RobotSpec, keyframe: str | None) -> InitialPose:
    """The robot's initial configuration, from its own compiled `model`.

    `keyframe` names one of the model's keyframes (a `ConfigError` listing them if absent);
    None: the robot's registered `home_qpos` if it has one (so101), else the keyframe named
    `home` if the model has it, else qpos0.
    """
    keys = [model.key(k).name for k in range(model.nkey)]
    if keyframe is None and not robot.home_qpos and "home" in keys:
        keyframe = "home"
    if keyframe is not None:
        if keyframe not in keys:
            valid = ", ".join(repr(k) for k in keys) or "(none)"
            raise ConfigError(
                f"option robot_keyframe={keyframe!r}: no such keyframe in {robot.name}; "
                f"valid: {valid}"
            )
        k = keys.index(keyframe)
        qpos = {
            model.joint(j).name: float(model.key_qpos[k, model.jnt_qposadr[j]])
            for j in range(model.njnt)
        }
        return InitialPose(qpos, np.array(model.key_ctrl[k]), f"keyframe {keyframe!r}")
    qpos = {
        model.joint(j).name: float(model.qpos0[model.jnt_qposadr[j]]) for j in range(model.njnt)
    }
    qpos.update(robot.home_qpos)
    return InitialPose(qpos, None, "home_qpos" if robot.home_qpos else "qpos0")


def held_ctrl(model: mujoco.MjModel, qpos: np.ndarray, ctrl: np.ndarray | None) -> np.ndarray:
    """Per actuator, the ctrl that holds it where it is at `qpos` (robot model, float64).

    From the keyframe's `ctrl` where there is one; else the servo's equilibrium at the
    actuator's length at `qpos`: gain * ctrl + bias0 + bias1 * length = 0. Used for actuators
    that drive no arm joint (a gripper's tendon), which scenes hold still.
    """
    if ctrl is not None:
        return np.asarray(ctrl, np.float64)
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    gain, bias = model.actuator_gainprm[:, 0], model.actuator_biasprm
    out = -(bias[:, 0] + bias[:, 1] * data.actuator_length) / np.where(gain != 0, gain, 1.0)
    return np.clip(out, model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1])


def cylinders_as_prisms(spec: mujoco.MjSpec, sides: int = 16) -> int:
    """Turn every colliding cylinder geom of `spec` into a convex `sides`-gon prism mesh.

    MJX's JAX implementation has no cylinder-box (nor cylinder-mesh) collision, and published
    arms collide through cylinders: a prism collides with boxes on every backend. The prism has
    the cylinder's length and cross-section area (vertex radius r * sqrt(pi / (n/2 sin(2pi/n))),
    within 1.3% of r everywhere for 16 sides) and its pose (a `fromto` one's made explicit).
    Returns how many geoms changed.
    """
    scale = math.sqrt(math.pi / (sides / 2 * math.sin(2 * math.pi / sides)))
    angles = 2 * math.pi * (np.arange(sides) + 0.5) / sides
    ring = np.stack([np.cos(angles), np.sin(angles)], axis=1) * scale
    changed = 0
    for geom in spec.geoms:
        if geom.type != mujoco.mjtGeom.mjGEOM_CYLINDER or (
            geom.contype == 0 and geom.conaffinity == 0
        ):
            continue
        r, half = float(geom.size[0]), float(geom.size[1])
        fromto = np.asarray(geom.fromto, np.float64)
        if not np.isnan(fromto).any():  # the axis from the first point to the second
            axis = fromto[3:] - fromto[:3]
            half = float(np.linalg.norm(axis)) / 2
            quat = np.zeros(4)
            mujoco.mju_quatZ2Vec(quat, axis)
            geom.pos = ((fromto[:3] + fromto[3:]) / 2).tolist()
            geom.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
            geom.quat = quat.tolist()
            geom.fromto = [math.nan] * 6
        verts = np.concatenate(
            [np.c_[ring * r, np.full(sides, -half)], np.c_[ring * r, np.full(sides, half)]]
        )
        mesh = spec.add_mesh(name=f"_prism_{changed}_{geom.name}")
        mesh.uservert = verts.reshape(-1).tolist()
        geom.type = mujoco.mjtGeom.mjGEOM_MESH
        geom.meshname = mesh.name
        changed += 1
    return changed


def for_mjx_jax(spec: mujoco.MjSpec, contacts_per_condim: int) -> dict[str, int]:
    """Make `spec` collide under MJX's JAX implementation, which has no cylinder-box or
    cylinder-mesh pair and no contact margin on mesh pairs: colliding cylinders become 16-gon
    prisms (`cylinders_as_prisms`), colliding geoms lose their margin and gap, and contact
    slots are capped at `contacts_per_condim` per condim (MJX's ``max_contact_points``; the
    `mjx` backend counts an env that may exceed it diverged). Returns what changed."""
    prisms = cylinders_as_prisms(spec)
    margins = 0
    for geom in spec.geoms:
        if (geom.contype or geom.conaffinity) and (geom.margin or geom.gap):
            geom.margin, geom.gap = 0.0, 0.0
            margins += 1
    spec.add_numeric(name="max_contact_points", data=[contacts_per_condim])
    return {
        "cylinders_as_prisms": prisms,
        "margins_zeroed": margins,
        "contacts_per_condim": contacts_per_condim,
    }


def geom_frame_offsets(
    before: mujoco.MjModel, after: mujoco.MjModel, geoms: Sequence[int]
) -> np.ndarray:
    """Per geom of `geoms`, the rotation q with ``after.geom_quat * q = before.geom_quat``
    (w-x-y-z, (len(geoms), 4)): a readout of the geom's orientation in model `after`, turned by
    q, is the one model `before` gives.

    A mesh geom's frame is its mesh's principal axes, which MuJoCo orders by moment: a prism
    from `cylinders_as_prisms` flatter than it is wide gets its axis as x, where the cylinder
    had z. Geom indices must be the same in both models (the prisms replace geoms in place).
    """
    out = np.zeros((len(geoms), 4))
    for i, g in enumerate(geoms):
        inverse = np.zeros(4)
        mujoco.mju_negQuat(inverse, after.geom_quat[g])
        mujoco.mju_mulQuat(out[i], inverse, before.geom_quat[g])
    return out
