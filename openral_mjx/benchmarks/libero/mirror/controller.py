"""robosuite's OSC_POSE controller and Panda gripper, as LIBERO runs them, in JAX.

robosuite recomputes the arm's torques at every 2 ms physics step from the state that step
starts in, toward a goal set once per 20 Hz control step (no interpolation, fixed impedance):

- goal: position = end effector + ``a[:3]`` scaled to ±0.05 m; orientation = the rotation
  ``a[3:6]`` scaled to ±0.5 rad (axis-angle) applied to the end effector's, except that an
  exactly zero rotation keeps the previous goal orientation (robosuite's `set_goal`);
- torques = ``J^T [Λ_pos F, Λ_ori T]`` with ``F = kp e_pos - kd v``, ``T = kp e_ori - kd w``
  (decoupled), plus the bias forces (gravity, Coriolis) and a nullspace pull toward the
  robot's initial pose (gain 10, critically damped); clipped to the actuators' limits;
- gripper: each physics step moves its command by 0.01 toward ``sign(a[6])`` (-1 open, 1
  closed) on each finger, mapped onto the two position servos' control ranges.

The dynamics robosuite reads from MuJoCo (end-effector pose, its Jacobian, the arm's mass
matrix and bias forces) come from a model of the robot alone (`RobotDynamics`), evaluated with
JAX: for the arm's joints those depend only on the robot's own bodies, and so this runs the
same on every physics backend.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct

from openral_mjx.core import fixed_order as fo
from openral_mjx.core.rotations import quat_to_mat_np

NULLSPACE_KP = 10.0  # robosuite's `nullspace_torques` gain


@struct.dataclass
class ControllerState:
    """What the controller carries between control steps (one env)."""

    goal_pos: jax.Array  # (3,)
    goal_ori: jax.Array  # (3, 3)
    gripper: jax.Array  # (2,) the fingers' commands in [-1, 1]


@struct.dataclass
class Dynamics:
    """What robosuite's controller reads of the robot's state."""

    ee_pos: jax.Array  # (3,)
    ee_mat: jax.Array  # (3, 3)
    jac: jax.Array  # (6, n_arm): position rows, then rotation rows
    mass: jax.Array  # (n_arm, n_arm)
    bias: jax.Array  # (n_arm,)


def robot_spec(spec: mujoco.MjSpec, root: str) -> mujoco.MjSpec:
    """A copy of `spec` with only body `root`'s subtree (the robot, as mounted) left, and no
    geoms: the inertials are explicit (`assets.physics_spec`), and nothing here collides.
    With no geom left, no mesh, texture or material is drawn either: they go too (a task's
    visual meshes, ~1 M vertices, took ~2 s to compile here for nothing)."""
    robot = spec.copy()
    for body in list(robot.worldbody.bodies):
        if body.name != root:
            robot.delete(body)
    for items in (robot.actuators, robot.sensors, robot.equalities, robot.tendons):
        for item in list(items):
            robot.delete(item)
    for item in [*robot.pairs, *robot.excludes, *robot.geoms]:
        robot.delete(item)
    for site in robot.sites:
        site.material = ""
    for item in [*robot.meshes, *robot.textures, *robot.materials]:
        robot.delete(item)
    return robot


class RobotDynamics:
    """The end-effector pose, Jacobian, mass matrix and bias forces of the arm, from the
    robot's joint positions and velocities (float32, pure JAX, one env).

    The robot is a tree of bodies with at most one hinge or slide joint each. Bodies without
    a joint are merged, at construction and in numpy, into the nearest body above them that
    moves, so the JAX side walks the joints only: the mass matrix sums each moving body's
    share at its centre of mass (plus the joints' armature), and the bias (gravity, Coriolis
    and centrifugal forces, MuJoCo's ``qfrc_bias``) is recursive Newton-Euler at zero joint
    acceleration, in world-frame spatial vectors. Both recursions run as sums over the
    ancestor matrix, with no loop over the tree. (MJX's `kinematics` of LIBERO's 22-body
    robot took 150 ms a call on a CPU, against about 1 ms here; differentiating the mass
    matrix for the bias instead made XLA compile this for 17 s on a CPU, against ~2 s; the
    tests check it against MuJoCo C.)
    """

    def __init__(
        self, spec: mujoco.MjSpec, full: mujoco.MjModel, joints: Sequence[str], site: str
    ) -> None:
        """`full`: `spec` compiled (where the robot's root body is found)."""
        body = full.body(full.joint(joints[0]).bodyid[0])
        while int(body.parentid[0]) != 0:
            body = full.body(int(body.parentid[0]))
        self.model = m = robot_spec(spec, body.name).compile()
        if np.any(np.bincount(m.jnt_bodyid, minlength=m.nbody) > 1) or np.any(
            ~np.isin(m.jnt_type, (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE))
        ):
            raise ValueError("RobotDynamics takes one hinge or slide joint per body at most")
        self.qpos_names = [m.joint(i).name for i in range(m.njnt)]
        self.arm_dofs = np.array([m.joint(j).dofadr[0] for j in joints])
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)  # every body's world pose at qpos0
        moving = np.zeros(m.nbody, int)  # each body's nearest moving ancestor-or-self (0: world)
        for b in range(1, m.nbody):
            has_joint = m.body_jntnum[b] > 0
            moving[b] = b if has_joint else moving[m.body_parentid[b]]
        frames = [int(m.jnt_bodyid[j]) for j in range(m.njnt)]  # joint j moves frame j
        frame_of = {b: k for k, b in enumerate(frames)}

        def relative(a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
            """Body b's pose in body a's frame at qpos0 (a = 0: the world)."""
            ra, pa = d.xmat[a].reshape(3, 3), d.xpos[a]
            return ra.T @ d.xmat[b].reshape(3, 3), ra.T @ (d.xpos[b] - pa)

        self._parent = [frame_of.get(int(moving[m.body_parentid[b]]), -1) for b in frames]
        rel = [relative(int(moving[m.body_parentid[b]]), b) for b in frames]
        self._rel_rot = np.array([r for r, _ in rel], np.float32)
        self._rel_pos = np.array([p for _, p in rel], np.float32)
        self._axis = m.jnt_axis.astype(np.float32)
        self._anchor = m.jnt_pos.astype(np.float32)
        self._hinge = m.jnt_type == mujoco.mjtJoint.mjJNT_HINGE
        self._dof = m.jnt_dofadr.copy()
        self._q0 = m.qpos0[m.jnt_qposadr].astype(np.float32)
        self._qadr = m.jnt_qposadr.copy()
        # composite inertia of each moving frame: mass, centre of mass and inertia about it
        mass = np.zeros(m.njnt)
        first = np.zeros((m.njnt, 3))
        second = np.zeros((m.njnt, 3, 3))
        for b in range(1, m.nbody):
            k = frame_of.get(int(moving[b]))
            if k is None or m.body_mass[b] == 0:
                continue  # fixed to the world: no share in the joints' dynamics
            r, p = relative(frames[k], b)
            ri = r @ quat_to_mat_np(m.body_iquat[b])
            com = p + r @ m.body_ipos[b]
            mb = m.body_mass[b]
            mass[k] += mb
            first[k] += mb * com
            second[k] += ri @ np.diag(m.body_inertia[b]) @ ri.T + mb * (
                np.dot(com, com) * np.eye(3) - np.outer(com, com)
            )
        com = first / np.maximum(mass, 1e-12)[:, None]
        about_com = second - mass[:, None, None] * (
            np.einsum("ki,ki->k", com, com)[:, None, None] * np.eye(3)
            - np.einsum("ki,kj->kij", com, com)
        )
        self._mass = mass.astype(np.float32)
        self._com = com.astype(np.float32)
        self._inertia = about_com.astype(np.float32)
        # ancestors[k, j]: joint j moves frame k
        ancestors = np.zeros((m.njnt, m.njnt), bool)
        for k in range(m.njnt):
            a = k
            while a >= 0:
                ancestors[k, a] = True
                a = self._parent[a]
        self._ancestors = ancestors
        site_id = m.site(site).id
        self._site_frame = frame_of[int(moving[m.site_bodyid[site_id]])]
        r, p = relative(frames[self._site_frame], int(m.site_bodyid[site_id]))
        self._site_pos = (p + r @ m.site_pos[site_id]).astype(np.float32)
        self._site_rot = (r @ quat_to_mat_np(m.site_quat[site_id])).astype(np.float32)
        self._armature = m.dof_armature.astype(np.float32)
        self._gravity = m.opt.gravity.astype(np.float32)

    def _frames(self, q: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
        """World rotations (K, 3, 3) and origins (K, 3) of the moving frames, and the joints'
        world axes and anchors (K, 3).

        Each frame's pose in its parent's comes first, for all frames at once (a hinge turns
        about its axis through its anchor, a slide shifts along it); then the chain composes
        them, parents first."""
        dq = q[self._qadr] - self._q0
        hinge = self._hinge[:, None]
        turn = jax.vmap(_rotation)(self._axis * dq[:, None])  # the identity for slides' dq 0
        turn = jnp.where(hinge[..., None], turn, jnp.eye(3))
        shift = jnp.where(
            hinge,
            self._anchor - fo.mv(turn, self._anchor),
            self._axis * dq[:, None],
        )
        rel_rot, rel_pos = self._rel_rot, self._rel_pos
        local_rot = fo.mm(rel_rot, turn)
        local_pos = rel_pos + fo.mv(rel_rot, shift)
        rots: list[jax.Array] = []
        poss: list[jax.Array] = []
        for k, parent in enumerate(self._parent):
            r0 = rots[parent] if parent >= 0 else jnp.eye(3)
            p0 = poss[parent] if parent >= 0 else jnp.zeros(3)
            rots.append(fo.mm(r0, local_rot[k]))
            poss.append(p0 + fo.mv(r0, local_pos[k]))
        rot, pos = jnp.stack(rots), jnp.stack(poss)
        axes = fo.mv(rot, self._axis)  # a turn keeps its own axis
        return rot, pos, axes, pos + fo.mv(rot, self._anchor)

    def _jacobians(
        self, points: jax.Array, frames: np.ndarray, axes: jax.Array, anchors: jax.Array
    ) -> jax.Array:
        """(P, 6, nv) Jacobians of world points (P, 3) fixed to moving frames `frames`."""
        hinge = jnp.asarray(self._hinge)[None, :, None]
        lever = points[:, None, :] - anchors[None]  # (P, K, 3)
        lin = jnp.where(hinge, jnp.cross(axes[None], lever), axes[None])
        ang = jnp.where(hinge, jnp.broadcast_to(axes[None], lever.shape), 0.0)
        mask = jnp.asarray(self._ancestors[frames])[..., None]  # (P, K, 1)
        cols = jnp.concatenate([lin, ang], axis=-1) * mask  # (P, K, 6)
        jac = jnp.zeros((points.shape[0], 6, self.model.nv))
        return jac.at[:, :, self._dof].set(jnp.swapaxes(cols, 1, 2))

    def _mass_matrix(
        self, rots: jax.Array, poss: jax.Array, axes: jax.Array, anchors: jax.Array
    ) -> tuple[jax.Array, jax.Array, jax.Array]:
        """The joint-space mass matrix (nv, nv), and the moving frames' world centres of mass
        (K, 3) and inertias about them (K, 3, 3)."""
        com = poss + fo.mv(rots, self._com)
        inertia = fo.mm(fo.mm(rots, self._inertia), jnp.swapaxes(rots, 1, 2))
        jac = self._jacobians(com, np.arange(len(self._parent)), axes, anchors)
        lin, ang = jac[:, :3], jac[:, 3:]
        shares = self._mass[:, None, None] * fo.mm(jnp.swapaxes(lin, 1, 2), lin)
        shares = shares + fo.mm(jnp.swapaxes(ang, 1, 2), fo.mm(inertia, ang))
        return fo.total(shares) + jnp.diag(self._armature), com, inertia

    def _bias(
        self, qd: jax.Array, axes: jax.Array, anchors: jax.Array, com: jax.Array, inertia: jax.Array
    ) -> jax.Array:
        """Recursive Newton-Euler at zero joint acceleration: the joints' bias forces (K,).

        Spatial vectors are (angular, linear at the world origin). Frame k's velocity is the
        sum of its ancestors' joint motions ``S_j qd_j``; its acceleration, gravity's (as the
        base accelerating upward) plus each ancestor's ``v_j x S_j qd_j``; the joints take the
        forces of the frames they carry."""
        unit = jnp.where(  # S_k: a hinge turns about its axis through its anchor
            jnp.asarray(self._hinge)[:, None],
            jnp.concatenate([axes, jnp.cross(anchors, axes)], -1),
            jnp.concatenate([jnp.zeros_like(axes), axes], -1),
        )
        motion = unit * qd[:, None]
        ancestors = jnp.asarray(self._ancestors, jnp.float32)  # [k, j]: j moves k
        vel = fo.mm(ancestors, motion)
        w, v = vel[:, :3], vel[:, 3:]
        m_w, m_v = motion[:, :3], motion[:, 3:]
        cross = jnp.concatenate([jnp.cross(w, m_w), jnp.cross(v, m_w) + jnp.cross(w, m_v)], -1)
        base = jnp.concatenate([jnp.zeros(3), -jnp.asarray(self._gravity)])
        acc = base + fo.mm(ancestors, cross)
        mass = jnp.asarray(self._mass)[:, None]

        def inertia_times(x: jax.Array) -> jax.Array:
            """Each frame's spatial inertia about the world origin times spatial vector x."""
            xw, xv = x[:, :3], x[:, 3:]
            v_com = xv + jnp.cross(xw, com)  # the linear part at the centre of mass
            force = mass * v_com
            moment = fo.mv(inertia, xw) + jnp.cross(com, force)
            return jnp.concatenate([moment, force], -1)

        momentum = inertia_times(vel)
        h_w, h_v = momentum[:, :3], momentum[:, 3:]
        force = inertia_times(acc) + jnp.concatenate(
            [jnp.cross(w, h_w) + jnp.cross(v, h_v), jnp.cross(w, h_v)], -1
        )
        return fo.dot(unit, fo.mm(ancestors.T, force))

    def __call__(self, qpos: jax.Array, qvel: jax.Array) -> Dynamics:
        rots, poss, axes, anchors = self._frames(qpos)
        k = self._site_frame
        site_pos = poss[k] + fo.mv(rots[k], self._site_pos)
        site_mat = fo.mm(rots[k], self._site_rot)
        jac = self._jacobians(site_pos[None], np.array([k]), axes, anchors)[0]
        mass, com, inertia = self._mass_matrix(rots, poss, axes, anchors)
        tau = self._bias(qvel[self._dof], axes, anchors, com, inertia)
        bias = jnp.zeros(self.model.nv, jnp.float32).at[self._dof].set(tau)
        dofs = self.arm_dofs
        return Dynamics(site_pos, site_mat, jac[:, dofs], mass[jnp.ix_(dofs, dofs)], bias[dofs])


@dataclasses.dataclass(frozen=True)
class OscGains:
    """robosuite's OSC_POSE constants for one task (read from LIBERO by the export)."""

    kp: np.ndarray  # (6,)
    kd: np.ndarray  # (6,)
    input_min: np.ndarray  # (6,)
    input_max: np.ndarray
    output_min: np.ndarray
    output_max: np.ndarray
    nullspace_pose: np.ndarray  # (n_arm,)
    torque_low: np.ndarray
    torque_high: np.ndarray
    gripper_speed: float
    gripper_low: np.ndarray  # (2,) the finger servos' control ranges
    gripper_high: np.ndarray


def _rotation(axis_angle: jax.Array) -> jax.Array:
    """Rotation matrix of an axis-angle vector (the identity at zero)."""
    angle = fo.norm(axis_angle)
    safe = jnp.where(angle > 0, angle, 1.0)
    k = axis_angle / safe
    kx = jnp.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    r = jnp.eye(3) + jnp.sin(angle) * kx + (1.0 - jnp.cos(angle)) * fo.mm(kx, kx)
    return jnp.where(angle > 0, r, jnp.eye(3))


def orientation_error(desired: jax.Array, current: jax.Array) -> jax.Array:
    """robosuite's `orientation_error`: half the sum of the column cross products."""
    return 0.5 * fo.total(jnp.cross(current.T, desired.T))


def set_goal(g: OscGains, c: ControllerState, action: jax.Array, dyn: Dynamics) -> ControllerState:
    """robosuite's `set_goal` for a 6-D arm action, from the state the control step starts in."""
    a = jnp.clip(action, g.input_min, g.input_max)
    scale = (g.output_max - g.output_min) / (g.input_max - g.input_min)
    delta = (a - (g.input_max + g.input_min) / 2) * scale + (g.output_max + g.output_min) / 2
    rotates = jnp.any(delta[3:] != 0)
    goal_ori = jnp.where(rotates, fo.mm(_rotation(delta[3:]), dyn.ee_mat), c.goal_ori)
    return c.replace(goal_pos=dyn.ee_pos + delta[:3], goal_ori=goal_ori)


def arm_torques(
    g: OscGains, c: ControllerState, dyn: Dynamics, q: jax.Array, qd: jax.Array
) -> jax.Array:
    """robosuite's `run_controller` (decoupled OSC) and the robot's torque clip; `q`, `qd`:
    the arm's joint positions and velocities.

    robosuite inverts the operational-space matrices ``J M^-1 J^T`` with `pinv`; with the
    Jacobian of full rank they are symmetric positive definite, and their inverse is the
    pseudo-inverse. All products here are summed in a fixed order (`fixed_order`), so a seed's
    torques do not depend on the batch it runs in."""
    jac, jac_t = dyn.jac, dyn.jac.T
    vel = fo.mv(jac, qd)
    force = g.kp[:3] * (c.goal_pos - dyn.ee_pos) - g.kd[:3] * vel[:3]
    torque = g.kp[3:] * orientation_error(c.goal_ori, dyn.ee_mat) - g.kd[3:] * vel[3:]
    m_inv = fo.inv_spd(dyn.mass)
    lam_full = fo.inv_spd(fo.mm(fo.mm(jac, m_inv), jac_t))
    jp, jr = jac[:3], jac[3:]
    lam_pos = fo.inv_spd(fo.mm(fo.mm(jp, m_inv), jp.T))
    lam_ori = fo.inv_spd(fo.mm(fo.mm(jr, m_inv), jr.T))
    wrench = jnp.concatenate([fo.mv(lam_pos, force), fo.mv(lam_ori, torque)])
    tau = fo.mv(jac_t, wrench) + dyn.bias
    jbar = fo.mm(fo.mm(m_inv, jac_t), lam_full)
    nullspace = jnp.eye(q.shape[0]) - fo.mm(jbar, jac)
    kv = 2.0 * np.sqrt(NULLSPACE_KP)
    pose = fo.mv(dyn.mass, NULLSPACE_KP * (g.nullspace_pose - q) - kv * qd)
    tau = tau + fo.mv(nullspace.T, pose)
    return jnp.clip(tau, g.torque_low, g.torque_high)


def gripper_step(
    g: OscGains, c: ControllerState, command: jax.Array
) -> tuple[ControllerState, jax.Array]:
    """One physics step of robosuite's Panda gripper: the new finger commands and the two
    servos' controls."""
    move = jnp.array([-1.0, 1.0]) * g.gripper_speed * jnp.sign(command)
    fingers = jnp.clip(c.gripper + move, -1.0, 1.0)
    bias = 0.5 * (g.gripper_high + g.gripper_low)
    weight = 0.5 * (g.gripper_high - g.gripper_low)
    return c.replace(gripper=fingers), bias + weight * fingers
