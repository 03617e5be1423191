"""What `tabletop_push` measures on its robot before anything runs (numpy and MuJoCo, once).

An arm comes as published: any size, a `home` keyframe or none, a flange of any size. From the
robot's own compiled model (root at the origin, turned by `robot_base_yaw`) this finds:

* the initial configuration (`composition.initial_pose`), and the ctrl that holds still the
  actuators that drive no joint (a gripper's tendon; `composition.held_ctrl`);
* the integrator: Euler (joint damping implicit; what the SO-101 is validated with on every
  backend), unless the MJCF asks for an implicit one or a servo's velocity gain would make
  Euler's explicit step ring (kv * dt / M_jj > 1 at the start, M the joint-space inertia):
  then implicitfast, as published arms with stiff servos are integrated;
* the tool, from the colliding geoms (contype or conaffinity set) of the end-effector site's
  body and its descendants at the initial configuration, in the site frame (+z out of the
  tool): how far they reach past the site along the tool axis (`tool_below`, which lifts the
  push height off the table), and how far sideways from the tool axis at the height of the
  cube while pushing (`tool_radius`, the expert's standoff; a `RobotSpec` may fix it);
* the reach: the horizontal distances from the base at which the site reaches the push height
  with the tool pointing down (within 30 degrees), found by the expert's own damped
  least-squares IK step from the initial configuration, outward and inward in 1 cm steps along
  the bearing the arm points to there (reach is taken to be the same at every bearing);
* the base placement: `robot_base_x` as set, checked to put the workspace (the box around the
  cube spawn range and the goal region, widened by the push standoff) within the reach, or,
  unset, 0 where that works, else the x that centres the workspace in the reach.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.policies.push_expert import DAMPING, MAX_STEP_M, ORIENT_WEIGHT, STANDOFF_GAP_M
from openral_mjx.robots import RobotSpec
from openral_mjx.scenes.composition import held_ctrl, initial_pose, load_robot
from openral_mjx.scenes.tabletop_push.options import TabletopPushOptions

# Reached: the site within this distance of the target, the tool axis within this angle of down.
REACH_TOL_M = 0.002
REACH_TILT = math.radians(30)
# Euler's explicit servo damping rings beyond this kv * dt / M_jj (diverges beyond 2).
EULER_LIMIT = 1.0
# Tool clearance above the table top while pushing, and above the cube top while hovering:
# the hover clearance grows with the arm's reach (its tracking error grows with its size).
PUSH_CLEARANCE_M = 0.003
HOVER_CLEARANCE_M = 0.04
HOVER_PER_REACH = 0.05


@dataclasses.dataclass(frozen=True)
class Reach:
    """Where the site gets to the push height with the tool pointing down: `near`..`far` (m)
    horizontally from the base, measured along `bearing` (rad, world frame)."""

    near: float
    far: float
    bearing: float


@dataclasses.dataclass(frozen=True)
class ArmSetup:
    """The robot as `tabletop_push` runs it: start pose, held actuators, tool, reach, base x.

    `push_height` is the site's height above the table top while pushing (m, tool pointing
    down), `hover_clearance` its height above the cube top while hovering; `held` maps the
    index of an actuator that drives no joint to the ctrl that holds it; `unreachable` says
    why the expert cannot work (None: it can).
    """

    qpos: dict[str, float]
    start: str
    integrator: mujoco.mjtIntegrator
    held: dict[int, float]
    tool_radius: float
    tool_below: float
    push_height: float
    hover_clearance: float
    base_x: float
    reach: Reach | None
    unreachable: str | None


def root_quat(model: mujoco.MjModel, yaw: float) -> np.ndarray:
    """The root body's orientation turned by `yaw` (rad) about world z."""
    out = np.zeros(4)
    turn = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    mujoco.mju_mulQuat(out, turn, np.asarray(model.body_quat[1], np.float64))
    return out


def place_root(spec: mujoco.MjSpec, pos: list[float], quat: np.ndarray) -> None:
    """Put the robot's root body at `pos` with orientation `quat` (replacing any euler/axis
    form the MJCF used)."""
    root = spec.worldbody.first_body()
    root.pos = pos
    root.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
    root.quat = list(quat)


def robot_alone(robot: RobotSpec, yaw: float) -> mujoco.MjModel:
    """The checked robot MJCF (`load_robot`) compiled alone, its root at the origin turned by
    `yaw` (the frame the measurements are made in)."""
    spec = load_robot(robot)
    place_root(spec, [0.0, 0.0, 0.0], root_quat(spec.copy().compile(), yaw))
    return spec.compile()


def integrator(model: mujoco.MjModel, qpos: np.ndarray, timestep: float) -> mujoco.mjtIntegrator:
    """Euler, or implicitfast where the MJCF asks for an implicit integrator or where a
    servo's velocity gain kv (-biasprm[2], through its transmission) would ring under Euler's
    explicit step at `timestep`: kv dt / M_jj > `EULER_LIMIT` for a joint it drives."""
    implicit = (mujoco.mjtIntegrator.mjINT_IMPLICIT, mujoco.mjtIntegrator.mjINT_IMPLICITFAST)
    if model.opt.integrator in implicit:
        return mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    moment = np.zeros((model.nu, model.nv))
    for i in range(model.nu):  # dense actuator moments (d length / d qpos)
        adr, n = data.moment_rowadr[i], data.moment_rownnz[i]
        moment[i, data.moment_colind[adr : adr + n]] = data.actuator_moment[adr : adr + n]
    affine = model.actuator_biastype == int(mujoco.mjtBias.mjBIAS_AFFINE)
    kv = np.where(affine, -model.actuator_biasprm[:, 2], 0.0)
    damping = (moment**2 * kv[:, None]).sum(axis=0)  # per dof
    ratio = damping * timestep / np.maximum(np.diag(mass), 1e-12)
    if np.any(ratio > EULER_LIMIT):
        return mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    return mujoco.mjtIntegrator.mjINT_EULER


# ---- tool ------------------------------------------------------------------------------------


def _sphere_dirs(n: int = 96) -> np.ndarray:
    """`n` unit vectors spread over the sphere (Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = math.pi * (1 + math.sqrt(5)) * i
    r = np.sqrt(1 - z**2)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _geom_points(model: mujoco.MjModel, g: int) -> np.ndarray:
    """Points on the surface of geom `g` in its own frame (dense enough for extents)."""
    size = model.geom_size[g]
    kind = int(model.geom_type[g])
    t = mujoco.mjtGeom
    angles = np.linspace(0, 2 * math.pi, 48, endpoint=False)
    ring = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    if kind in (int(t.mjGEOM_SPHERE), int(t.mjGEOM_ELLIPSOID)):
        radii = size if kind == int(t.mjGEOM_ELLIPSOID) else np.full(3, size[0])
        return _sphere_dirs() * radii
    if kind in (int(t.mjGEOM_CAPSULE), int(t.mjGEOM_CYLINDER)):
        r, half = size[0], size[1]
        levels = np.linspace(-half, half, 9)
        side = np.concatenate([ring * r + [0, 0, z] for z in levels])
        if kind == int(t.mjGEOM_CYLINDER):
            return side
        d, cap = _sphere_dirs() * r, np.array([0.0, 0.0, half])
        return np.concatenate([side, d + cap, d - cap])
    if kind == int(t.mjGEOM_BOX):
        grid = np.stack(np.meshgrid(*[np.linspace(-1, 1, 5)] * 3), -1).reshape(-1, 3)
        return grid[np.abs(grid).max(axis=1) == 1] * size
    if kind == int(t.mjGEOM_MESH):
        m = int(model.geom_dataid[g])
        vert = model.mesh_vert[
            model.mesh_vertadr[m] : model.mesh_vertadr[m] + model.mesh_vertnum[m]
        ]
        face = model.mesh_face[
            model.mesh_faceadr[m] : model.mesh_faceadr[m] + model.mesh_facenum[m]
        ]
        # Vertices and points along the face edges (a tall face may have no vertex at the
        # cube's height).
        a, b = vert[face].reshape(-1, 3), vert[np.roll(face, 1, axis=1)].reshape(-1, 3)
        w = np.linspace(0, 1, 6)[:, None, None]
        return np.concatenate([vert, ((1 - w) * a + w * b).reshape(-1, 3)])
    return np.zeros((0, 3))  # planes, height fields: not part of a tool


def tool_points(model: mujoco.MjModel, site: int, qpos: np.ndarray) -> np.ndarray:
    """Surface points of the colliding geoms of the site's body and its descendants at
    `qpos`, in the site's frame."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    root = int(model.site_bodyid[site])
    in_tree = np.zeros(model.nbody, bool)
    for b in range(model.nbody):  # parents come before children
        in_tree[b] = b == root or (b > 0 and in_tree[model.body_parentid[b]])
    site_pos, site_mat = data.site_xpos[site], data.site_xmat[site].reshape(3, 3)
    out = [np.zeros((0, 3))]
    for g in range(model.ngeom):
        if not in_tree[model.geom_bodyid[g]]:
            continue
        if model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0:
            continue
        world = data.geom_xpos[g] + _geom_points(model, g) @ data.geom_xmat[g].reshape(3, 3).T
        out.append((world - site_pos) @ site_mat)
    return np.concatenate(out)


def tool_extent(points: np.ndarray, cube_size: float, push_height: float) -> tuple[float, float]:
    """(below, radius) of the tool's points in the site frame: how far they reach past the site
    along +z (>= 0), and their farthest distance from the z axis among those at the cube's
    height when the site is `push_height` above the table, pointing down."""
    if points.shape[0] == 0:
        return 0.0, 0.0
    below = max(0.0, float(points[:, 2].max()))
    height = push_height - points[:, 2]  # above the table top
    band = points[(height >= 0) & (height <= cube_size)]
    radius = float(np.hypot(band[:, 0], band[:, 1]).max()) if band.shape[0] else 0.0
    return below, radius


# ---- reach -----------------------------------------------------------------------------------


class _Ik:
    """The expert's damped least-squares step (position, plus a weak pull of the tool axis
    towards -z), on the robot model alone, within joint limits."""

    def __init__(self, model: mujoco.MjModel, site: int) -> None:
        self.model, self.site = model, site
        self.data = mujoco.MjData(model)
        limited = model.jnt_limited.astype(bool)
        lo = np.full(model.nq, -np.inf)
        hi = np.full(model.nq, np.inf)
        adr = model.jnt_qposadr
        lo[adr[limited]], hi[adr[limited]] = model.jnt_range[limited].T
        self.lo, self.hi = lo, hi
        self.jacp = np.zeros((3, model.nv))
        self.jacr = np.zeros((3, model.nv))

    def pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Site position and tool axis (site +z) at `q`, world frame; fills the Jacobians."""
        m, d = self.model, self.data
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_jacSite(m, d, self.jacp, self.jacr, self.site)
        return d.site_xpos[self.site].copy(), d.site_xmat[self.site].reshape(3, 3)[:, 2].copy()

    def solve(self, q: np.ndarray, target: np.ndarray, iters: int) -> tuple[np.ndarray, bool]:
        """Step from `q` towards `target` up to `iters` times; whether it got there."""
        down = np.array([0.0, 0.0, -1.0])
        for _ in range(iters):
            pos, axis = self.pose(q)
            err = target - pos
            dist = float(np.linalg.norm(err))
            if dist < REACH_TOL_M and -axis[2] >= math.cos(REACH_TILT):
                return q, True
            err *= min(1.0, MAX_STEP_M / (dist + 1e-9))
            jp = self.jacp
            ja = np.cross(self.jacr.T, axis).T  # d(axis)/dq
            a = jp.T @ jp + ORIENT_WEIGHT * ja.T @ ja + DAMPING * np.eye(q.shape[0])
            dq = np.linalg.solve(a, jp.T @ err + ORIENT_WEIGHT * ja.T @ (down - axis))
            q = np.clip(q + dq, self.lo, self.hi)
        pos, axis = self.pose(q)
        ok = np.linalg.norm(target - pos) < REACH_TOL_M and -axis[2] >= math.cos(REACH_TILT)
        return q, bool(ok)


def measure_reach(
    model: mujoco.MjModel, site: int, q0: np.ndarray, height: float, step: float = 0.01
) -> Reach | None:
    """The horizontal distances from the base (the model's origin) at which the site reaches
    `height` with the tool pointing down, along the bearing it points to at `q0`; None if it
    reaches no such point (within 2 m)."""
    ik = _Ik(model, site)
    pos, _ = ik.pose(q0)
    bearing = math.atan2(pos[1], pos[0]) if math.hypot(pos[0], pos[1]) > 0.01 else 0.0
    u = np.array([math.cos(bearing), math.sin(bearing), 0.0])

    def target(r: float) -> np.ndarray:
        return r * u + [0.0, 0.0, height]

    start = round(max(math.hypot(pos[0], pos[1]), step) / step) * step
    # From the initial configuration, the first radius reached (nearest the start first).
    candidates = sorted(np.arange(step, 2.0, 5 * step), key=lambda r: abs(r - start))
    for r0 in [start, *candidates]:
        q, ok = ik.solve(q0.copy(), target(r0), 150)
        if ok:
            break
    else:
        return None
    bounds = []
    for direction in (-1, 1):
        r, qr = r0, q
        while 0 <= r + direction * step <= 2.0:
            qn, ok = ik.solve(qr, target(r + direction * step), 40)
            if not ok:
                break
            r, qr = r + direction * step, qn
        bounds.append(r)
    return Reach(round(bounds[0], 3), round(bounds[1], 3), bearing)


# ---- placement -------------------------------------------------------------------------------


def workspace(o: TabletopPushOptions, standoff: float) -> tuple[np.ndarray, np.ndarray]:
    """The box (low xy, high xy) the tool works in: around the cube spawn range and the goal
    region, widened by the push standoff."""
    lo = np.array(
        [min(o.cube_spawn_x[0], o.goal_region_x[0]), min(o.cube_spawn_y[0], o.goal_region_y[0])]
    )
    hi = np.array(
        [max(o.cube_spawn_x[1], o.goal_region_x[1]), max(o.cube_spawn_y[1], o.goal_region_y[1])]
    )
    return lo - standoff, hi + standoff


def span(lo: np.ndarray, hi: np.ndarray, base: np.ndarray) -> tuple[float, float]:
    """Nearest and farthest horizontal distance from `base` to the box [lo, hi]."""
    gap = np.maximum(np.maximum(lo - base, base - hi), 0.0)
    far = np.maximum(np.abs(lo - base), np.abs(hi - base))
    return float(np.hypot(*gap)), float(np.hypot(*far))


def _margin(reach: Reach, box: tuple[np.ndarray, np.ndarray], base: np.ndarray) -> float:
    """How far inside the reach the workspace box lies from `base` (< 0: partly outside)."""
    near, far = span(*box, base)
    return min(near - reach.near, reach.far - far)


def best_base_x(reach: Reach, box: tuple[np.ndarray, np.ndarray], base_y: float) -> float | None:
    """The x (5 mm grid) that centres the workspace box in the reach, the box in front of
    the arm (along its measured bearing); None if no x fits."""
    xs = np.round(np.arange(-3.0, 3.0 + 1e-9, 0.005), 3)
    ahead = math.cos(reach.bearing)
    centre = (box[0][0] + box[1][0]) / 2
    best, best_margin = None, 0.0
    for x in xs:
        if abs(ahead) > 0.1 and (centre - x) * ahead < 0:
            continue
        margin = _margin(reach, box, np.array([x, base_y]))
        if margin >= best_margin:
            best, best_margin = float(x), margin
    return best


def prepare(o: TabletopPushOptions, robot: RobotSpec) -> ArmSetup:
    """Load and check the robot, measure it, place its base (see the module docstring).

    `ConfigError` for a missing keyframe, or an explicit `robot_base_x` from which the arm does
    not reach the workspace (naming an x that does, if one does). Unset, an arm that reaches
    it from nowhere stays at 0 with `unreachable` set: other policies may still run.
    """
    model = robot_alone(robot, o.robot_base_yaw)
    pose = initial_pose(model, robot, o.robot_keyframe)
    q0 = np.array(model.qpos0)
    for name, value in pose.qpos.items():
        q0[model.joint(name).qposadr[0]] = value
    joint = int(mujoco.mjtTrn.mjTRN_JOINT)
    others = [i for i in range(model.nu) if int(model.actuator_trntype[i]) != joint]
    ctrl = held_ctrl(model, q0, pose.ctrl) if others else np.zeros(model.nu)
    site = model.site(robot.ee_site).id
    points = tool_points(model, site, q0)
    half = o.cube_size / 2
    below, _ = tool_extent(points, o.cube_size, 0.0)
    push = max(0.9 * half, below + PUSH_CLEARANCE_M)
    _, measured = tool_extent(points, o.cube_size, push)
    radius = robot.tool_radius if robot.tool_radius is not None else measured
    reach = measure_reach(model, site, q0, push)
    hover = max(HOVER_CLEARANCE_M, below + HOVER_PER_REACH * (reach.far if reach else 0.0))
    box = workspace(o, half + radius + STANDOFF_GAP_M)
    x = 0.0 if o.robot_base_x is None else o.robot_base_x
    unreachable, best = None, None
    if reach is None:
        unreachable = (
            f"{robot.name} cannot bring its site {robot.ee_site!r} to {push:.4f} m above the "
            "table with the tool (the site's +z) pointing down"
        )
    elif _margin(reach, box, np.array([x, o.robot_base_y])) < 0:
        near, far = span(*box, np.array([x, o.robot_base_y]))
        unreachable = (
            f"{robot.name} reaches {reach.near:.2f}-{reach.far:.2f} m from its base with the "
            f"tool pointing down, the workspace (spawn range and goal region) spans "
            f"{near:.2f}-{far:.2f} m from it"
        )
        best = best_base_x(reach, box, o.robot_base_y)
    if unreachable is not None and o.robot_base_x is not None:
        fix = (
            f"set robot_base_x={best:g}, or leave it unset to place the base from the reach"
            if best is not None
            else "no robot_base_x puts the workspace within reach"
        )
        raise ConfigError(f"option robot_base_x={x:g}: {unreachable}; {fix}")
    if best is not None:  # unset: placed from the measured reach
        x, unreachable = best, None
    return ArmSetup(
        qpos=pose.qpos,
        start=pose.source,
        integrator=integrator(model, q0, o.timestep),
        held={i: float(ctrl[i]) for i in others},
        tool_radius=float(radius),
        tool_below=below,
        push_height=push,
        hover_clearance=hover,
        base_x=x,
        reach=reach,
        unreachable=unreachable,
    )
