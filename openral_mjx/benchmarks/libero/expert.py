"""`libero-expert`: a scripted pick-and-place policy for LIBERO tasks, from privileged state.

It plays the goal's pick-and-place atoms (``On``, ``In``; the first two) one after another:
grasp the object, carry it over the target, lower it, let go and rise. It reads the
observation's ``state`` (lerobot's 8 floats: end-effector position first) and ``expert``
entry (per atom, the object's position, the target body's position and orientation; on both
the `libero` host scene and the `libero_mjx` mirror),
and acts as a pure JAX function of them, so the same seed plays the same actions on LIBERO and
on the mirror for as long as their states agree: the closed-loop oracle of the mirror's
agreement table.

What it knows of a task beyond the observation is fixed per task and computed here from the
task's model (the mirror's export, `assets.load_task`) at LIBERO's initial state 0:

- where to grasp, relative to the object's origin: the middle of the object's colliding
  geoms where they fit between the fingers (7 cm), else a point of the rim on the fingers'
  closing axis (bowls, baskets), 2 cm below the top;
- where the target is: the target body's origin (``On`` an object), or the region's site
  (``On`` a region, ``In`` a region) from the target body's pose, and the height to let go
  at: the object's bottom 2 cm above the target's top (its highest colliding geom, or the
  region's top face).

Phases (the policy state, with the atom being played): approach above the grasp point,
descend, close the gripper, lift, carry over the target, lower, open, retreat; after the
retreat, the next atom's approach. Position targets become OSC deltas
(``(target - eef) / 0.05``, clipped to [-1, 1]: robosuite scales a unit action to 5 cm); the
orientation is held (zero rotation). Atoms that are not pick-and-place (opening, closing,
turning on or off) are not played: a goal with one succeeds only where it already holds.
`coverage` says which a task is.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.benchmarks.libero.assets import load_task, physics_spec
from openral_mjx.benchmarks.libero.export import ATOM_SIZE, EXPERT_SIZE, pick_atoms
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.rotations import quat_to_mat
from openral_mjx.physics.contact_sensors import in_subtree
from openral_mjx.policies.base import Policy

SCENES = ("libero", "libero_mjx")
OSC_SCALE = 0.05  # metres per unit of position action (robosuite's OSC_POSE output_max)
FINGER_GAP = 0.07  # widest object part grasped across its middle
ABOVE = 0.10  # approach height over the grasp point
CLEARANCE = 0.02  # the object's bottom over the target's top when let go
CARRY = 0.12  # carrying height over the release height
APPROACH, DESCEND, CLOSE, LIFT, CARRY_OVER, LOWER, OPEN, RETREAT = range(8)
GRIPPER_STEPS = 15  # control steps the gripper gets to close or open
PHASE_LIMIT = 80  # control steps after which a moving phase gives up waiting and goes on
RETREATED = 0.01  # how near the retreat point the hand is before the next atom's approach


@dataclasses.dataclass(frozen=True)
class Plan:
    """The per-task constants the expert plays with (see the module docstring), one row per
    pick-and-place atom it plays, in the goal's order."""

    grasp: np.ndarray  # grasp point relative to the object's origin, world axes (atoms, 3)
    site_pos: np.ndarray  # the target point in the target body's frame (atoms, 3)
    release_z: np.ndarray  # object-origin height over the target point when let go (atoms,)
    coverage: str

    @property
    def atoms(self) -> int:
        return len(self.release_z)


def _colliding_box(m: mujoco.MjModel, d: mujoco.MjData, body: int) -> tuple[np.ndarray, ...]:
    """World-axis bounds (low, high) of the colliding geoms in `body`'s subtree."""
    lows, highs = [], []
    for g in range(m.ngeom):
        if not (m.geom_contype[g] or m.geom_conaffinity[g]):
            continue
        if not in_subtree(m, int(m.geom_bodyid[g]), body):
            continue
        center, half = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
        corners = center + half * np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T
        world = d.geom_xpos[g] + corners @ d.geom_xmat[g].reshape(3, 3).T
        lows.append(world.min(axis=0))
        highs.append(world.max(axis=0))
    if not lows:
        raise ConfigError(f"body {m.body(body).name!r} has no colliding geom to grasp")
    return np.min(lows, axis=0), np.max(highs, axis=0)


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
    """Task ``suite/index``'s plan, or None where its goal has no pick-and-place atom."""
    export = load_task(task)
    picks = pick_atoms(export.goal)
    if not picks:
        return None
    m = physics_spec(export).compile()
    d = mujoco.MjData(m)
    state = np.asarray(export.init_states[0], np.float64)
    d.qpos[:] = state[1 : 1 + m.nq]
    mujoco.mj_forward(m, d)
    axis = closing_axis(m, d, export.meta["gripper_joints"][0])
    rows = [_atom_plan(m, d, atom, axis) for atom in picks]
    others = [a for a in export.goal if a["kind"] != "true" and a not in picks]
    return Plan(
        grasp=np.stack([r[0] for r in rows]).astype(np.float32),
        site_pos=np.stack([r[1] for r in rows]).astype(np.float32),
        release_z=np.array([r[2] for r in rows], np.float32),
        coverage="pick-and-place atoms of several" if others else "covered",
    )


def _atom_plan(
    m: mujoco.MjModel, d: mujoco.MjData, atom: dict[str, Any], axis: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:
    """One pick-and-place atom's grasp point, target point and release height."""
    obj = m.body(atom["obj"]).id
    target = m.body(atom.get("target") or atom["site_body"]).id
    low, high = _colliding_box(m, d, obj)
    origin = d.xpos[obj]
    width = float((high - low) @ axis)
    grasp = (low + high) / 2 - origin
    if width > FINGER_GAP:  # the rim on the closing axis, 1 cm in from the edge
        grasp = grasp + axis * (width / 2 - 0.01)
    grasp[2] = high[2] - origin[2] - min(0.02, (high[2] - low[2]) / 2)
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
    return grasp, site_pos, float(top + CLEARANCE + bottom)


def _mat(quat: Any) -> np.ndarray:
    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.asarray(quat, np.float64))
    return out.reshape(3, 3)


def coverage(task: str) -> str:
    """Whether the expert plays `task`'s goal: ``covered`` (every atom, each a
    pick-and-place), ``pick-and-place atoms of several`` (it plays those; the others, such as
    opening or turning on, it does not), or ``not covered`` (no pick-and-place atom)."""
    plan = plan_for(task)
    return "not covered" if plan is None else plan.coverage


def _toward(target: jax.Array, eef: jax.Array, gripper: float | jax.Array) -> jax.Array:
    delta = jnp.clip((target - eef) / OSC_SCALE, -1.0, 1.0)
    return jnp.concatenate([delta, jnp.zeros(3), jnp.reshape(jnp.float32(gripper), (1,))])


def act(plan: Plan, state: jax.Array, expert: jax.Array, pstate: dict) -> tuple[jax.Array, dict]:
    """One control step of the expert: the action and the next phase state. It plays the
    plan's atoms one after another: after the retreat from one, the next one's approach."""
    eef = state[:3]
    phase, count, atom = pstate["phase"], pstate["count"], pstate["atom"]
    row = jax.lax.dynamic_slice(expert, (atom * ATOM_SIZE,), (ATOM_SIZE,))
    obj, target_pos, target_quat = row[:3], row[3:6], row[6:10]
    grasp = obj + jnp.asarray(plan.grasp)[atom]
    goal = target_pos + quat_to_mat(target_quat) @ jnp.asarray(plan.site_pos)[atom]
    held = obj - eef  # the object's origin relative to the hand, once held
    release_z = jnp.asarray(plan.release_z)[atom]
    release = jnp.concatenate([goal[:2] - held[:2], goal[2:] + release_z - held[2:]])
    carry = release[2] + CARRY
    targets = jnp.stack(
        [
            grasp + jnp.array([0.0, 0.0, ABOVE]),  # APPROACH
            grasp,  # DESCEND
            pstate["hold"],  # CLOSE
            # LIFT: at least 5 cm up from where the object was grasped
            jnp.concatenate(
                [pstate["hold"][:2], jnp.maximum(carry, pstate["hold"][2] + 0.05)[None]]
            ),
            jnp.concatenate([release[:2], carry[None]]),  # CARRY_OVER
            release,  # LOWER
            pstate["hold"],  # OPEN
            pstate["hold"] + jnp.array([0.0, 0.0, ABOVE]),  # RETREAT
        ]
    )
    grip = jnp.array([-1.0, -1.0, 1.0, 1.0, 1.0, 1.0, -1.0, -1.0])
    target = targets[phase]
    action = _toward(target, eef, grip[phase])
    error = jnp.linalg.norm(target - eef)
    reached = jnp.array([0.01, 0.006, 0.0, 0.015, 0.01, 0.008, 0.0, 0.0])[phase]
    timed = jnp.array([PHASE_LIMIT, 40, GRIPPER_STEPS, PHASE_LIMIT, PHASE_LIMIT, 40, 10, 10**6])
    advance = ((error < reached) | (count + 1 >= timed[phase])) & (phase < RETREAT)
    # the next atom, once the hand is back up from this one (the last one's retreat holds)
    next_atom = (
        (phase == RETREAT)
        & (atom + 1 < plan.atoms)
        & ((error < RETREATED) | (count + 1 >= PHASE_LIMIT))
    )
    moved = advance | next_atom
    return action, {
        "phase": jnp.where(next_atom, APPROACH, phase + advance.astype(jnp.int32)),
        "count": jnp.where(moved, 0, count + 1),
        "atom": atom + next_atom.astype(jnp.int32),
        # where the hand holds still while the gripper moves: where it was when that began
        "hold": jnp.where(moved, eef, pstate["hold"]),
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
            f"policy 'libero-expert' picks and places: task {scene.task!r}'s goal has no On or "
            "In atom (opening, closing and turning are not scripted)"
        )
    if name == "libero_mjx" and scene.obs_layout:  # a flat vector (no cameras)
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
