"""`libero-expert`: a scripted policy for LIBERO tasks, from privileged state.

It plays the goal's atoms one after another, in `export.expert_atoms`' order (what opens or
turns on first, then the pick-and-place atoms, then what closes or turns off):

- **pick-and-place** (``On``, ``In``): grasp the object, carry it over the target, lower it,
  let go and rise;
- **push** (``TurnOn``/``TurnOff`` of a knob, ``Close`` of a hinged door or of a cabinet's
  top drawer): the closed gripper goes beside the moving part's contact point, on the side
  away from where it must move, and pushes it along its path (an arc about a hinge, a line
  along a slide; for a drawer the hand first turns a quarter about the vertical, so that its
  palm lies along the cabinet's front) in strokes of `STROKE` steps, going up and down
  behind the part again after each, until the joint is past the goal's threshold. Pushing a
  hinge back to rest (a knob off, a door shut) the drive aims `PRESS` low, so the hand presses
  down as it pushes (level, it rode 2 cm up over a knob's handle and the knob turned back:
  `libero_90/39`); turning a knob on it pushes level (pressing, LIBERO's knob stuck on 4 of
  `libero_goal/7`'s 50 seeds).

Not played (the atom is skipped; `coverage` says which tasks the expert plays in full):
opening a drawer (hooking or grasping its handle: from above the palm, 21 cm across the
fingers' closing axis, stops on the cabinet; turned, the closed fingers do not fit the 2 cm
between handle and front), shutting any drawer but a cabinet's top one (the palm meets the
cabinet above it), opening a hinged door (the microwave: its handle needs a grasp the
downward hand cannot make), picking an object whose grasp the open fingers cannot reach for
a part of something else over it once the objects have settled (a bowl in a cabinet's open
top drawer, half under the cabinet's top: `libero_spatial/4`), and placing into a region
with a part of its target's fixture over it (inside the microwave, on or under a cabinet's
shelf, inside a shut drawer: reached from the side or not at all, where the straight-down
placing lands the object on top).

It reads the observation's ``state`` (lerobot's 8 floats: end-effector position first) and
``expert`` entry (`export.expert_entry`: per atom the object's position and the target body's
pose, or the moving body's pose and the joint's position; on both the `libero` host scene
and the `libero_mjx` mirror), and acts as a pure JAX function of them, so the same seed plays
the same actions on LIBERO and on the mirror for as long as their states agree: the
closed-loop oracle of the mirror's agreement table.

What it knows of a task beyond the observation is fixed per task and computed here from the
task's model (the mirror's export, `assets.load_task`) at LIBERO's initial state 0:

- where to grasp, relative to the object's origin: the middle of the object's colliding
  geoms where they fit between the fingers (7 cm), 2 cm below the top; else a knob standing
  over the rest (a moka pot's lid), the fingertips clear of the lid; else a handle reaching
  out past the rest (a frying pan's), near the body, the hand turned a quarter where the
  handle lies along the fingers' closing axis; else a point of the rim on the closing axis
  (bowls, baskets), 2 cm below the top;
- where objects put on one region stand: side by side across it, not on one point;
- where the target is: the target body's origin (``On`` an object), or the region's site
  (``On`` a region, ``In`` a region) from the target body's pose, and the height to let go
  at: the object's bottom 2 cm above the target's top (its highest colliding geom, or the
  region's top face);
- for a joint atom, in the moving body's frame: the joint's axis and anchor, and the contact
  point: on a hinge the point of the moving part's tallest colliding geoms farthest from the
  axis (found with the joint at zero, however it starts), on a drawer its handle's outer face.

Phases (the policy state, with the atom being played): approach above the start point
(from higher up, after one atom's retreat, the hand crosses to the next object level and then
comes down, not on a diagonal through what it has just let go over), descend, close the
gripper, lift (a joint atom: drive along the path), carry over the target, lower, open,
retreat; after the retreat, the next atom's approach. A grasp whose fingers close on nothing
(under `EMPTY` apart while lifting, carrying or lowering) starts the atom over from its
approach. Position targets become OSC deltas (``(target - eef) / 0.05``, clipped to
[-1, 1]: robosuite scales a unit action to 5 cm); the orientation is held (zero rotation),
except in a drawer's push and a handle's pick, which first turn the hand to their heading.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.benchmarks.libero.assets import load_task, physics_spec
from openral_mjx.benchmarks.libero.export import ATOM_SIZE, EXPERT_SIZE, closes, expert_atoms
from openral_mjx.core import fixed_order as fo
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.rotations import quat_to_mat
from openral_mjx.physics.contact_sensors import in_subtree
from openral_mjx.policies.base import Policy

SCENES = ("libero", "libero_mjx")
OSC_SCALE = 0.05  # metres per unit of position action (robosuite's OSC_POSE output_max)
FINGER_GAP = 0.07  # widest object part grasped across its middle
KNOB = 0.015  # m: a part standing this far above the rest of a wide object is grasped alone
TIP = 0.013  # m: the fingertips' reach below the grip site (robosuite's Panda gripper)
TIP_CLEAR = 0.003  # m: the fingertips' clearance over what a knob stands on
SIDE_GAP = 0.01  # m: between objects put side by side on one region
HANDLE_RATIO = 3.0  # a handle is at least this many times as long as it is wide
HANDLE_OUT = 0.05  # m: and reaches at least this far beyond the rest of its object
HANDLE_IN = 0.03  # m: grasped this far from its inner end
PAD_UP = 0.004  # m: the finger pads' middle over the grip site (robosuite's Panda gripper)
ABOVE = 0.10  # approach height over the grasp point
CROSSED = 0.02  # m: a hand crossing level to a grasp comes down once this near it
CLEARANCE = 0.02  # the object's bottom over the target's top when let go
CARRY = 0.12  # carrying height over the release height
APPROACH, DESCEND, CLOSE, LIFT, CARRY_OVER, LOWER, OPEN, RETREAT = range(8)
GRIPPER_STEPS = 15  # control steps the gripper gets to close or open
EMPTY = 0.003  # the fingers' gap (m) under which a closed grasp holds nothing (a bowl's rim: 6 mm)
PHASE_LIMIT = 80  # control steps after which a moving phase gives up waiting and goes on
RETREATED = 0.01  # how near the retreat point the hand is before the next atom's approach
PICK, PUSH, SKIP = range(3)  # how an atom is played
STANDOFF = 0.055  # a push's start: the hand's centre this far behind the contact point
INSET = 0.01  # a push's contact point: this far in from the part's far end, towards the axis
FINGER = 0.01  # a push's drive: the hand's centre this far behind the point it pushes to
PRESS = 0.01  # a hinge's push back to rest aims this far low: the hand presses, not riding up
AHEAD = 0.05  # how far along its path a joint atom's drive aims ahead of the contact point
TOP_DRAWER = 0.02  # m: a drawer whose cabinet rises no higher over its top is the top one
TURNED = 0.05  # rad: the hand's heading counts as reached within this
STROKE = 25  # control steps a push's drive gets; if the joint is not past by then, the hand
# goes up and comes down behind the part again (a long push wedges the fingers on a knob)
WIDE_HINGE = 0.1  # a hinge whose contact point lies farther from its axis is a door
ROOF = 0.03  # m: a part of the target this far over a region's site makes it reached from the side


@dataclasses.dataclass(frozen=True)
class Plan:
    """The per-task constants the expert plays with (see the module docstring), one row per
    atom of `export.expert_atoms`, in its order."""

    kind: np.ndarray  # PICK, PUSH or SKIP (atoms,)
    # PICK: the grasp point relative to the object's origin, world axes; a joint atom: the
    # contact point in the moving body's frame (atoms, 3)
    point: np.ndarray
    site_pos: np.ndarray  # PICK: the target point in the target body's frame (atoms, 3)
    release_z: np.ndarray  # PICK: object-origin height over the target point when let go
    axis: np.ndarray  # a joint atom: the joint's axis in the moving body's frame (atoms, 3)
    anchor: np.ndarray  # a hinge: its anchor in the moving body's frame
    slide: np.ndarray  # a joint atom: a slide (a drawer), else a hinge (atoms,)
    yaw: np.ndarray  # a drawer, a handle: the hand's heading (world yaw, rad) to play it with
    turn: np.ndarray  # whether the hand turns to `yaw` first, else it holds its heading (atoms,)
    sign: np.ndarray  # a joint atom: +1 where the goal wants the joint above its threshold
    threshold: np.ndarray  # a joint atom: the goal's threshold on the joint's position
    press: np.ndarray  # a push's drive aims this far below the contact point (atoms,)
    coverage: str

    @property
    def atoms(self) -> int:
        return len(self.kind)


def _colliding_geoms(m: mujoco.MjModel, body: int) -> list[int]:
    """The colliding geoms in `body`'s subtree, in the model's order."""
    return [
        g
        for g in range(m.ngeom)
        if (m.geom_contype[g] or m.geom_conaffinity[g])
        and in_subtree(m, int(m.geom_bodyid[g]), body)
    ]


def _geom_boxes(m: mujoco.MjModel, d: mujoco.MjData, body: int) -> list[tuple[np.ndarray, ...]]:
    """World-axis bounds (low, high) of each colliding geom in `body`'s subtree, in the order
    of `_colliding_geoms`."""
    boxes = []
    for g in _colliding_geoms(m, body):
        center, half = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
        corners = center + half * np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T
        world = d.geom_xpos[g] + corners @ d.geom_xmat[g].reshape(3, 3).T
        boxes.append((world.min(axis=0), world.max(axis=0)))
    if not boxes:
        raise ConfigError(f"body {m.body(body).name!r} has no colliding geom to grasp or push")
    return boxes


def _bounds(boxes: list[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, np.ndarray]:
    """World-axis bounds (low, high) around `boxes`."""
    return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)


def _colliding_box(m: mujoco.MjModel, d: mujoco.MjData, body: int) -> tuple[np.ndarray, ...]:
    """World-axis bounds (low, high) of the colliding geoms in `body`'s subtree."""
    return _bounds(_geom_boxes(m, d, body))


def _quarter_turn(yaw: float) -> float:
    """A heading a quarter turn from `yaw`, wrapped to (-pi, pi]."""
    return float(np.angle(np.exp(1j * (yaw + np.pi / 2))))


def closing_axis(m: mujoco.MjModel, d: mujoco.MjData, finger_joint: str) -> np.ndarray:
    """The world axis (x or y) the gripper's fingers close along, at `d`."""
    j = m.joint(finger_joint)
    axis = d.xmat[j.bodyid[0]].reshape(3, 3) @ m.jnt_axis[j.id]
    out = np.zeros(3)
    k = int(np.argmax(np.abs(axis[:2])))
    out[k] = 1.0
    return out


@functools.cache
def plan_for(task: str) -> Plan | None:
    """Task ``suite/index``'s plan, or None where the expert plays none of its atoms."""
    export = load_task(task)
    atoms = expert_atoms(export.goal)
    m = physics_spec(export).compile()
    d = mujoco.MjData(m)
    state = np.asarray(export.init_states[0], np.float64)
    d.qpos[:] = state[1 : 1 + m.nq]
    mujoco.mj_forward(m, d)
    axis = closing_axis(m, d, export.meta["gripper_joints"][0])
    hand = d.xmat[m.body(export.meta["eef_body"]).id].reshape(3, 3)
    yaw = float(np.arctan2(hand[1, 0], hand[0, 0]))
    blocked = _grasp_blocked(m, d, export.meta)
    rows = [
        _joint_plan(m, d, atom, yaw)
        if atom["kind"] == "joints"
        else _atom_plan(m, d, atom, axis, yaw)
        for atom in atoms
    ]
    rows = [
        {"kind": SKIP} if r["kind"] == PICK and blocked(atom["obj"], r["point"]) else r
        for atom, r in zip(atoms, rows, strict=True)
    ]
    _side_by_side(atoms, rows, lambda body: d.xmat[m.body(body).id].reshape(3, 3))
    played = [r for r in rows if r["kind"] != SKIP]
    if not played:
        return None
    goal = [a for a in export.goal if a["kind"] != "true"]
    full = len(played) == len(goal)
    stack = lambda k, dtype=np.float32: np.array([r.get(k, 0.0) for r in rows], dtype)  # noqa: E731
    vec = lambda k: np.stack([np.asarray(r.get(k, np.zeros(3)), np.float32) for r in rows])  # noqa: E731
    return Plan(
        kind=stack("kind", np.int32),
        point=vec("point"),
        site_pos=vec("site_pos"),
        release_z=stack("release_z"),
        axis=vec("axis"),
        anchor=vec("anchor"),
        slide=stack("slide", bool),
        yaw=stack("yaw"),
        turn=stack("turn", bool),
        sign=stack("sign"),
        threshold=stack("threshold"),
        press=stack("press"),
        coverage="covered" if full else "partly",
    )


def _atom_plan(
    m: mujoco.MjModel, d: mujoco.MjData, atom: dict[str, Any], axis: np.ndarray, yaw: float
) -> dict[str, Any]:
    """One pick-and-place atom's grasp point, target point and release height, and the
    hand's heading for it (`yaw`, the heading at the initial state, unless it grasps a
    handle that lies along the closing axis)."""
    obj = m.body(atom["obj"]).id
    target = m.body(atom.get("target") or atom["site_body"]).id
    boxes = _geom_boxes(m, d, obj)
    low, high = _bounds(boxes)
    origin = d.xpos[obj]
    width = float((high - low) @ axis)
    grasp = (low + high) / 2 - origin
    grasp[2] = high[2] - origin[2] - min(0.02, (high[2] - low[2]) / 2)
    knob = _knob(boxes, axis) if width > FINGER_GAP else None
    handle = _handle(boxes) if width > FINGER_GAP and knob is None else None
    turn = False
    if knob is not None:  # a lid's knob, the fingertips clear of the lid
        grasp = knob - origin
    elif handle is not None:  # a pan's handle, the fingers closing across it
        point, along, i = handle
        point[2] = _bar_height(m, d, _colliding_geoms(m, obj)[i], point) - PAD_UP
        grasp, turn = point - origin, bool(abs(along @ axis) > 0.5)
    elif width > FINGER_GAP:  # the rim on the closing axis, 1 cm in from the edge
        grasp = grasp + axis * (width / 2 - 0.01)
    bottom = origin[2] - low[2]  # the object's origin over its bottom
    if atom["kind"] == "on_object":
        site_pos = np.zeros(3)
        _, t_high = _colliding_box(m, d, target)
        top = t_high[2] - d.xpos[target][2]
    else:
        site_pos = np.asarray(atom["site_pos"], np.float64)
        rot = d.xmat[target].reshape(3, 3) @ _mat(atom["site_quat"])
        top = float(np.abs(rot @ np.asarray(atom["size"]))[2])
        if atom["kind"] == "on_site":
            top = float(atom["size"][2])
        site = d.xpos[target] + d.xmat[target].reshape(3, 3) @ site_pos
        # over the site, any part of the whole fixture counts: a closed drawer's inside lies
        # under the cabinet's top, not under the drawer (`libero_goal/3`)
        fixture = int(m.body_rootid[target])
        if _colliding_geoms(m, target) and _roofed(_geom_boxes(m, d, fixture), site):
            return {"kind": SKIP}  # (a region on a body with no colliding part has no roof)
    return {
        "kind": PICK,
        "point": grasp,
        "site_pos": site_pos,
        "release_z": float(top + CLEARANCE + bottom),
        "footprint": (high - low)[:2],
        "yaw": _quarter_turn(yaw) if turn else yaw,
        "turn": turn,
    }


def _grasp_blocked(
    m: mujoco.MjModel, d: mujoco.MjData, meta: dict[str, Any]
) -> Callable[[str, np.ndarray], bool]:
    """Whether the open fingers, brought straight down to an object's grasp point (relative
    to the object's origin), would meet a part of another body over the object's top: the
    fingers' colliding geoms (world-axis bounds, about the grip site, as the hand holds them
    at `d`) against the other bodies' (not the robot's, not the object's) once LIBERO's
    settle steps have let the objects come to rest (the robot held). A bowl that settles in
    a cabinet's open top drawer sits half under the cabinet's top, on whose edge the inner
    finger stops 3.6 cm short of the grasp (`libero_spatial/4`: 0 of 200 on LIBERO and on
    the mirror; the bounds overlap by 1 mm). The palm is left out: its mesh's bounds, 21 cm
    long, meet a taller neighbour the real palm passes over (`libero_object/3`'s salad
    dressing, where the expert succeeds 200 of 200)."""
    site = d.site_xpos[m.site(meta["eef_site"]).id].copy()
    fingers = [int(m.joint(j).bodyid[0]) for j in meta["gripper_joints"]]
    hand = [(low - site, high - site) for f in fingers for low, high in _geom_boxes(m, d, f)]
    settled = _settled(m, d, meta)
    robot = int(m.body_rootid[m.body(meta["eef_body"]).id])

    def blocked(obj_name: str, grasp: np.ndarray) -> bool:
        obj = m.body(obj_name).id
        top = _bounds(_geom_boxes(m, settled, obj))[1][2]
        at = settled.xpos[obj] + grasp
        others = sorted({int(r) for r in m.body_rootid[1:]} - {int(m.body_rootid[obj]), robot})
        over = [b for r in others for b in _geom_boxes(m, settled, r) if b[0][2] > top]
        return any(
            np.all(h_low + at < high) and np.all(low < h_high + at)
            for h_low, h_high in hand
            for low, high in over
        )

    return blocked


def _settled(m: mujoco.MjModel, d: mujoco.MjData, meta: dict[str, Any]) -> mujoco.MjData:
    """A copy of `d` after LIBERO's settle steps (`settle_steps` control steps of
    `n_substeps` physics steps) with the robot's joints held where `d` has them."""
    out = copy.copy(d)
    joints = [m.joint(j) for j in (*meta["arm_joints"], *meta["gripper_joints"])]
    qadr = np.array([j.qposadr[0] for j in joints])
    vadr = np.array([j.dofadr[0] for j in joints])
    held = out.qpos[qadr].copy()
    for _ in range(int(meta["settle_steps"]) * int(meta["n_substeps"])):
        mujoco.mj_step(m, out)
        out.qpos[qadr], out.qvel[vadr] = held, 0.0
    mujoco.mj_forward(m, out)
    return out


def _roofed(boxes: list[tuple[np.ndarray, ...]], point: np.ndarray) -> bool:
    """Whether one of a target fixture's parts (`boxes`, world-axis bounds) lies `ROOF` or
    more over `point` (world): a region reached from the side, which the expert's
    straight-down placing cannot enter. A mug let down over the microwave's inside lands on
    its top (`libero_10/9`); a pan or a book over a cabinet's shelf, on the cabinet
    (`libero_90` 40, 42, 86, 88, 89); a bowl over a shut drawer's inside, on the cabinet
    (`libero_goal/3`, `libero_90/8`: its top 3.5 cm over the site). A burner or a plate's rim
    just over its region's site is no roof (3 cm: of the 130 tasks only those two drawers'
    coverage changed from 5 cm, 2026-12-02)."""
    return any(
        low[2] > point[2] + ROOF and np.all(low[:2] <= point[:2]) and np.all(point[:2] <= high[:2])
        for low, high in boxes
    )


def _handle(boxes: list[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, np.ndarray, int] | None:
    """Where to grasp a handle, the world axis it lies along and its index in `boxes`, or
    None. A handle is a colliding part at least `HANDLE_RATIO` times as long as it is wide,
    narrower than the fingers open, that reaches `HANDLE_OUT` beyond the rest of the
    object. It is grasped `HANDLE_IN` from its inner end (near the body, where the object's
    weight turns it least), 1.5 cm below its top (`_atom_plan` then puts the grasp on the
    bar's axis). LIBERO's frying pan is 20 cm across; its rim on the closing axis was the
    handle's end, which the fingers closed along."""
    best = None
    for i, (low, high) in enumerate(boxes):
        size = (high - low)[:2]
        k = int(np.argmax(size))
        if size[k] < HANDLE_RATIO * size[1 - k] or size[1 - k] > FINGER_GAP / 2:
            continue
        rest = [b for j, b in enumerate(boxes) if j != i]
        if not rest:
            continue
        r_low, r_high = _bounds(rest)
        out, inner = (
            (high[k] - r_high[k], low[k]) if high[k] > r_high[k] else (r_low[k] - low[k], high[k])
        )
        if out < HANDLE_OUT or (best is not None and out <= best[0]):
            continue
        point = (low + high) / 2
        point[k] = inner + np.sign(point[k] - inner) * HANDLE_IN
        point[2] = high[2] - min(0.015, (high[2] - low[2]) / 2)
        best = (out, point, np.eye(3)[k], i)
    return None if best is None else best[1:]


def _bar_height(m: mujoco.MjModel, d: mujoco.MjData, geom: int, point: np.ndarray) -> float:
    """The height of box `geom`'s long axis over `point`'s horizontal position. A sloping
    bar's world-axis bounds are taller than the bar: the pan's handle is 1.2 cm thick and
    rises 1.7 cm along its 13 cm, and grasped at its bounds' middle, 5 mm over the bar, it
    slipped from the fingers (`libero_90/18`: 4 of 10 seeds)."""
    rot, centre = d.geom_xmat[geom].reshape(3, 3), d.geom_xpos[geom]
    u = rot[:, int(np.argmax(m.geom_size[geom]))]
    t = float((point - centre)[:2] @ u[:2]) / max(float(u[:2] @ u[:2]), 1e-12)
    return float(centre[2] + t * u[2])


def _side_by_side(
    atoms: list[dict[str, Any]],
    rows: list[dict[str, Any]],
    frame: Callable[[str], np.ndarray],
) -> None:
    """Objects put `On` the same region stand side by side in it, `SIDE_GAP` apart along the
    world axis they are narrower in, not on one point: `libero_10/8`'s second moka pot came
    down on the first. (`In` a container the objects may land on each other, as LIBERO's
    demonstrations drop them.) Moves those rows' `site_pos` in place; `frame(body)` is the
    rotation matrix of the region's body, whose frame `site_pos` is in."""
    groups: dict[tuple[Any, ...], list[int]] = {}
    for i, (atom, row) in enumerate(zip(atoms, rows, strict=True)):
        if row["kind"] == PICK and atom["kind"] == "on_site":
            groups.setdefault((atom["site_body"], tuple(atom["site_pos"])), []).append(i)
    for (body, _), members in groups.items():
        if len(members) < 2:
            continue
        widths = np.array([rows[i]["footprint"] for i in members])
        k = int(np.argmin(widths.max(axis=0)))
        ends = np.cumsum(widths[:, k] + SIDE_GAP) - SIDE_GAP
        centres = ends - widths[:, k] / 2 - ends[-1] / 2
        rot = frame(body)
        for i, c in zip(members, centres, strict=True):
            rows[i]["site_pos"] = rows[i]["site_pos"] + rot.T @ (np.eye(3)[k] * c)


def _knob(boxes: list[tuple[np.ndarray, ...]], axis: np.ndarray) -> np.ndarray | None:
    """Where to grasp a part that stands at least `KNOB` above the rest of the object and
    fits between the fingers (a moka pot's lid knob), or None: over its middle, the grip
    site `TIP` + `TIP_CLEAR` above the rest, so the fingertips come down clear of it. The
    moka pot is wider than the fingers open across both axes (8.2 cm), and its rim on the
    closing axis is its spout or handle, which the fingers close on at an angle."""
    top = max(hi[2] for _, hi in boxes)
    at_top = [b[1][2] >= top - 0.005 for b in boxes]
    parts = [b for b, up in zip(boxes, at_top, strict=True) if up]
    rest = [b for b, up in zip(boxes, at_top, strict=True) if not up]
    if not rest:
        return None
    rest_top = max(hi[2] for _, hi in rest)
    low, high = _bounds(parts)
    if top - rest_top < KNOB or float((high - low) @ axis) > FINGER_GAP:
        return None
    point = (low + high) / 2
    point[2] = rest_top + TIP + TIP_CLEAR
    return point


def _joint_plan(
    m: mujoco.MjModel, d: mujoco.MjData, atom: dict[str, Any], yaw: float
) -> dict[str, Any]:
    """One joint atom's contact point, axis and anchor (in the moving body's frame), or SKIP
    where the expert does not play it (see the module docstring); `yaw` is the hand's heading
    at the initial state."""
    j = m.joint(atom["joints"][0])
    body = int(j.bodyid[0])
    slide = int(j.type[0]) == mujoco.mjtJoint.mjJNT_SLIDE
    if not slide:
        # A hinged part as its joint's zero sets it: the world-axis bounds of its geoms are
        # then as tight as its model draws them. Turned (a knob already on, 0.98 rad, to be
        # turned off), a bar's bounds are a square whose face centres lie off the bar, and the
        # hand pushed it 2 cm from its axis, where it would not turn (`libero_90/39`).
        d = _with_joint_at(m, d, j, 0.0)
    rot, origin = d.xmat[body].reshape(3, 3), d.xpos[body]
    axis_w, anchor_w = rot @ m.jnt_axis[j.id], d.xanchor[j.id]
    boxes = _geom_boxes(m, d, body)
    sign = 1.0 if atom["above"][0] else -1.0
    if slide:
        if not closes(atom):
            # Opening a drawer needs its handle hooked or grasped: from above, the palm
            # (21 cm across the fingers' closing axis) stopped on the cabinet over
            # `libero_goal/0`'s handle, and turned, the closed fingers do not fit the 2 cm
            # between handle and front.
            return {"kind": SKIP}
        # Shut: push the handle's outer face with the hand turned a quarter about the
        # vertical, so the palm lies along the front. Unturned, it spans the drawer's axis
        # and met the cabinet 3 cm short (`libero_90/0`). Turned, it still meets the
        # cabinet over any drawer but the top one (`libero_90/22`'s bottom drawer: 3.7 cm
        # short): those are not played.
        fixture = body
        while m.body_parentid[fixture] != 0:
            fixture = int(m.body_parentid[fixture])
        over = max(b[1][2] for b in _geom_boxes(m, d, fixture)) - max(b[1][2] for b in boxes)
        if over > TOP_DRAWER:
            return {"kind": SKIP}
        opening = -sign * axis_w
        low, high = max(
            boxes,
            key=lambda b: (b[0] + b[1]) @ opening / 2 + np.abs(b[1] - b[0]) @ np.abs(opening) / 2,
        )
        point = (low + high) / 2 + opening * (np.abs(high - low) @ np.abs(opening)) / 2
    else:
        top = max(high[2] for _, high in boxes)
        faces = [  # the face centres of the tallest parts' boxes
            ((low + high) / 2 + np.eye(3)[k] * side * (high - low)[k] / 2, (low, high))
            for low, high in boxes
            if high[2] >= top - 0.02
            for k in range(3)
            for side in (-1, 1)
        ]
        radial = lambda p: float(np.linalg.norm(np.cross(axis_w, p - anchor_w)))  # noqa: E731
        point, (low, high) = max(faces, key=lambda f: radial(f[0]))
        if not closes(atom) and radial(point) > WIDE_HINGE:  # a door to open
            return {"kind": SKIP}
        # a little in from the far end (pushed at its tip, the part turns out from under the
        # fingers and wedges them)
        lever = np.cross(axis_w, np.cross(point - anchor_w, axis_w))
        point = point - INSET * lever / np.linalg.norm(lever)
    point = point.copy()  # high enough to clear what the part stands on, low enough to push
    point[2] = min(high[2] - 0.015, max((low[2] + high[2]) / 2, low[2] + 0.03))
    return {
        "kind": PUSH,
        "point": rot.T @ (point - origin),
        "axis": np.asarray(m.jnt_axis[j.id], np.float64),
        "anchor": rot.T @ (anchor_w - origin),
        "slide": slide,
        "yaw": _quarter_turn(yaw),
        "turn": slide,
        "sign": sign,
        "threshold": float(atom["threshold"][0]),
        "press": PRESS if closes(atom) and not slide else 0.0,
    }


def _with_joint_at(m: mujoco.MjModel, d: mujoco.MjData, joint: Any, q: float) -> mujoco.MjData:
    """A copy of `d` with `joint`'s position set to `q`, its poses recomputed."""
    out = mujoco.MjData(m)
    out.qpos[:] = d.qpos
    out.qpos[int(joint.qposadr[0])] = q
    mujoco.mj_kinematics(m, out)
    return out


def _mat(quat: Any) -> np.ndarray:
    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.asarray(quat, np.float64))
    return out.reshape(3, 3)


def coverage(task: str) -> str:
    """Whether the expert plays `task`'s goal: ``covered`` (every atom), ``partly`` (some:
    beside them a drawer or a door it does not play), or ``not covered`` (none)."""
    plan = plan_for(task)
    return "not covered" if plan is None else plan.coverage


def _toward(target: jax.Array, eef: jax.Array, gripper: float | jax.Array) -> jax.Array:
    delta = jnp.clip((target - eef) / OSC_SCALE, -1.0, 1.0)
    return jnp.concatenate([delta, jnp.zeros(3), jnp.reshape(jnp.float32(gripper), (1,))])


def _pick_targets(plan: Plan, row: jax.Array, atom: jax.Array, eef: jax.Array, hold: jax.Array):
    """A pick-and-place atom's target per phase (8, 3)."""
    obj, target_pos, target_quat = row[:3], row[3:6], row[6:10]
    grasp = obj + jnp.asarray(plan.point)[atom]
    goal = target_pos + quat_to_mat(target_quat) @ jnp.asarray(plan.site_pos)[atom]
    held = obj - eef  # the object's origin relative to the hand, once held
    release_z = jnp.asarray(plan.release_z)[atom]
    release = jnp.concatenate([goal[:2] - held[:2], goal[2:] + release_z - held[2:]])
    carry = release[2] + CARRY
    # above the grasp point; from higher up (after an atom's retreat) the hand first crosses
    # level, then comes down, as from `ABOVE`: on the diagonal down, a finger hooked the
    # basket's wall it had just let go over and lifted the basket away (`libero_10/1`)
    above = grasp + jnp.array([0.0, 0.0, ABOVE])
    over = fo.norm(eef[:2] - grasp[:2]) < CROSSED
    approach = jnp.where(over, above, above.at[2].max(hold[2]))
    return jnp.stack(
        [
            approach,  # APPROACH
            grasp,  # DESCEND
            hold,  # CLOSE
            # LIFT: at least 5 cm up from where the object was grasped
            jnp.concatenate([hold[:2], jnp.maximum(carry, hold[2] + 0.05)[None]]),
            jnp.concatenate([release[:2], carry[None]]),  # CARRY_OVER
            release,  # LOWER
            hold,  # OPEN
            hold + jnp.array([0.0, 0.0, ABOVE]),  # RETREAT
        ]
    )


def _heading_error(axis_angle: jax.Array, yaw: jax.Array) -> jax.Array:
    """`yaw` less the hand's heading (the yaw of its x axis), wrapped to (-pi, pi]; the hand's
    orientation as lerobot's state gives it (axis-angle)."""
    angle = fo.norm(axis_angle)
    x = _rotate(jnp.array([1.0, 0.0, 0.0]), axis_angle / jnp.maximum(angle, 1e-9), angle)
    d = yaw - jnp.arctan2(x[1], x[0])
    return jnp.arctan2(jnp.sin(d), jnp.cos(d))


def _rotate(v: jax.Array, axis: jax.Array, angle: jax.Array) -> jax.Array:
    """`v` turned by `angle` about the unit `axis` (Rodrigues)."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    return v * c + fo.cross(axis, v) * s + axis * fo.dot(axis, v) * (1.0 - c)


def _joint_targets(plan: Plan, row: jax.Array, atom: jax.Array, hold: jax.Array):
    """A joint atom's target per phase (8, 3), and whether the joint is past the goal's
    threshold. The drive aims `AHEAD` along the contact point's path: a line on a slide, an
    arc about a hinge."""
    pos, q, rot = row[:3], row[3], quat_to_mat(row[6:10])
    point = pos + fo.mv(rot, jnp.asarray(plan.point)[atom])
    axis = fo.mv(rot, jnp.asarray(plan.axis)[atom])
    lever = point - (pos + fo.mv(rot, jnp.asarray(plan.anchor)[atom]))
    sign, slide = jnp.asarray(plan.sign)[atom], jnp.asarray(plan.slide)[atom]
    tangent = jnp.where(slide, axis, fo.cross(axis, lever))
    way = sign * tangent / jnp.maximum(fo.norm(tangent), 1e-6)  # where the point must move
    radius = jnp.maximum(fo.norm(lever), 0.02)
    arc = point - lever + _rotate(lever, axis, sign * AHEAD / radius)
    ahead = jnp.where(slide, point + way * AHEAD, arc)
    press = jnp.asarray(plan.press)[atom]
    start, drive = point - way * STANDOFF, ahead - way * FINGER - jnp.array([0.0, 0.0, 1.0]) * press
    up = jnp.array([0.0, 0.0, ABOVE])
    targets = jnp.stack([start + up, start, hold, drive, hold, hold, hold, hold - way * AHEAD + up])
    return targets, sign * (q - jnp.asarray(plan.threshold)[atom]) > 0


# per way of playing an atom (PICK, PUSH, SKIP) and phase: the gripper's command, the
# distance at which a moving phase counts as reached, and the steps a phase gets at most
# (a phase a way skips gets one)
GRIP = np.array(
    [
        [-1.0, -1.0, 1.0, 1.0, 1.0, 1.0, -1.0, -1.0],
        [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0],
        [-1.0] * 8,
    ],
    np.float32,
)
REACHED = np.array(
    [
        [0.01, 0.006, 0.0, 0.015, 0.01, 0.008, 0.0, 0.0],
        [0.01, 0.008, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.0] * 8,
    ],
    np.float32,
)
TIMED = np.array(
    [
        [PHASE_LIMIT, 40, GRIPPER_STEPS, PHASE_LIMIT, PHASE_LIMIT, 40, 10, 10**6],
        [PHASE_LIMIT, 40, 1, STROKE, 1, 1, 1, 10**6],
        [1, 1, 1, 1, 1, 1, 1, 1],
    ],
    np.int32,
)


def act(plan: Plan, state: jax.Array, expert: jax.Array, pstate: dict) -> tuple[jax.Array, dict]:
    """One control step of the expert: the action and the next phase state. It plays the
    plan's atoms one after another: after the retreat from one, the next one's approach."""
    eef = state[:3]
    phase, count, atom, hold = pstate["phase"], pstate["count"], pstate["atom"], pstate["hold"]
    row = jax.lax.dynamic_slice(expert, (atom * ATOM_SIZE,), (ATOM_SIZE,))
    kind = jnp.asarray(plan.kind)[atom]
    joint_targets, past = _joint_targets(plan, row, atom, hold)
    targets = jnp.where(kind == PICK, _pick_targets(plan, row, atom, eef, hold), joint_targets)
    target = jnp.where(kind == SKIP, eef, targets[phase])
    action = _toward(target, eef, jnp.asarray(GRIP)[kind, phase])
    # a drawer's push and a handle's pick turn the hand first (robosuite turns its goal by
    # the action's axis-angle, 0.5 rad per unit, in world axes); other atoms hold the heading
    turn = _heading_error(state[3:6], jnp.asarray(plan.yaw)[atom])
    turning = jnp.asarray(plan.turn)[atom] & (jnp.abs(turn) > TURNED)
    action = action.at[5].set(jnp.where(turning, jnp.clip(turn / 0.5, -1.0, 1.0), 0.0))
    error = jnp.linalg.norm(target - eef) + jnp.where(turning, 1.0, 0.0)
    reached = jnp.where(
        (kind != PICK) & (phase == LIFT), past, error < jnp.asarray(REACHED)[kind, phase]
    )
    advance = (reached | (count + 1 >= jnp.asarray(TIMED)[kind, phase])) & (phase < RETREAT)
    # the next atom, once the hand is back up from this one (the last one's retreat holds)
    next_atom = (
        (phase == RETREAT)
        & (atom + 1 < plan.atoms)
        & ((error < RETREATED) | (count + 1 >= PHASE_LIMIT) | (kind == SKIP))
    )
    # a push's stroke that ends short of the threshold: up, and behind the part again; a
    # grasp that closed on nothing: up, and down over the object again (carried on, the
    # empty hand's carry height, set from where the object is, would climb without bound)
    stroke_short = (kind == PUSH) & (phase == LIFT) & ~past & (count + 1 >= STROKE)
    holding = (phase == LIFT) | (phase == CARRY_OVER) | (phase == LOWER)
    missed = (kind == PICK) & holding & (state[6] - state[7] < EMPTY)
    again = stroke_short | missed
    moved = advance | next_atom
    return action, {
        "phase": jnp.where(next_atom | again, APPROACH, phase + advance.astype(jnp.int32)),
        "count": jnp.where(moved, 0, count + 1),
        "atom": atom + next_atom.astype(jnp.int32),
        # where the hand holds still while the gripper moves: where it was when that began
        "hold": jnp.where(moved, eef, hold),
    }


def libero_expert(scene: Any, arg: str | None) -> Policy:
    """The expert for `scene` (`libero` or `libero_mjx`, with the ``expert`` option on)."""
    if arg is not None:
        raise ConfigError(f"policy 'libero-expert' takes no argument, got :{arg}")
    name = getattr(scene, "name", None)
    if name not in SCENES:
        raise ConfigError(
            f"policy 'libero-expert' plays LIBERO tasks: it runs on --scene libero or "
            f"libero_mjx, not {name!r}"
        )
    if not scene.options.expert:
        raise ConfigError("policy 'libero-expert' reads the expert entry: drop --opt expert=false")
    plan = plan_for(scene.task)
    if plan is None:
        raise ConfigError(
            f"policy 'libero-expert' plays no atom of task {scene.task!r}'s goal (drawers, "
            "opening a hinged door and placing into a region reached from the side are not "
            "scripted)"
        )
    if scene.obs_layout:  # a flat vector (no cameras)
        (s0, sn), (e0, en) = scene.obs_layout["state"], scene.obs_layout["expert"]

        def views(obs: Any) -> tuple[jax.Array, jax.Array]:
            return obs[s0 : s0 + sn], obs[e0 : e0 + en]
    else:

        def views(obs: Any) -> tuple[jax.Array, jax.Array]:
            return obs["state"], obs["expert"]

    def init(key, obs_spec):
        del key, obs_spec
        return None, {
            "phase": jnp.zeros((), jnp.int32),
            "count": jnp.zeros((), jnp.int32),
            "atom": jnp.zeros((), jnp.int32),
            "hold": jnp.zeros(3, jnp.float32),
        }

    def policy_act(params, pstate, obs, key):
        del params, key
        state, expert = views(obs)
        assert expert.shape[-1] == EXPERT_SIZE
        return act(plan, state.astype(jnp.float32), expert.astype(jnp.float32), pstate)

    return Policy("libero-expert", init, policy_act, cache_key="libero-expert", per_task=True)
