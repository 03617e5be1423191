"""What the LIBERO mirror needs of a task, read from LIBERO itself (runs in a worker of the
``lerobot-libero`` environment; numpy and LIBERO only).

`TaskExport(task).model()` builds LIBERO's `OffScreenRenderEnv` for ``suite/index`` (through
the host scene's env, so LIBERO's config and assets are set up the same way) and returns:

- ``xml``: the MJCF robosuite composes for the task (its own `get_xml`, which keeps the
  compiler's ``inertiagrouprange``; MuJoCo's saved XML drops it, and a body's inertia then
  counts its visual meshes: LIBERO's objects came out up to 4x heavier that way);
- the compiled model's body inertials (``body_mass``, ``body_inertia``, ``body_ipos``,
  ``body_iquat``), so the mirror can pin them whatever its compiler infers, and its body
  poses after `reset` (``body_pos``, ``body_quat``): LIBERO places its fixtures by writing
  them into the compiled model, not the MJCF; and its geom and site colours after `reset`
  (``geom_rgba``, ``site_rgba``: it hides sites by their alpha there);
- the task's 50 shipped initial states, flattened as MuJoCo's ``[time, qpos, qvel]``;
- robosuite's OSC_POSE controller constants (gains, action scaling, the nullspace pose,
  torque limits), the gripper's speed and actuators, and the controller's state after
  `reset` (the goal orientation a zero rotation keeps, the gripper's current command, and
  the robot state it read then, which the first step after `set_init_state` still uses);
- the names the mirror reads (end-effector site and body, arm joints and actuators).

`TaskExport.rollout` plays a fixed action sequence from one initial state and records what
the agreement tests compare.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from openral_mjx.benchmarks.libero.worker_env import DUMMY_ACTION, SETTLE_STEPS, LiberoEnv

# the ``expert`` observation entry: per atom of the goal the expert plays (`expert_atoms`, at
# most `EXPERT_ATOMS`) one row of `ATOM_SIZE` floats: for a pick-and-place atom the moved
# object's position, its target body's position and quaternion; for a joint atom (open, close,
# turn on or off) the moving body's position, the joint's position and two zeros, the moving
# body's quaternion; zeros where the goal has fewer
EXPERT_ATOMS = 3
ATOM_SIZE = 10
EXPERT_SIZE = EXPERT_ATOMS * ATOM_SIZE
PICK_KINDS = ("on_object", "on_site", "in_site")
# LIBERO's articulated objects' method for each joint predicate
_METHODS = {"open": "is_open", "close": "is_close", "turnon": "turn_on", "turnoff": "turn_off"}


class TaskExport:
    """One LIBERO task, built once; see the module docstring."""

    def __init__(self, task: str, image_size: int = 16) -> None:
        # only `camera_states` reads the images: small unless it asks
        self.host = LiberoEnv(task, image_size=image_size, expert=True)
        self.env = self.host.env.env  # robosuite's environment under LIBERO's wrapper

    def _reset(self, init: int, sampled: bool = False) -> None:
        self.host.reset(seed=0, options={"init_state": init, "sampled": sampled})

    def model(self) -> dict[str, Any]:
        env = self.env
        self.host.env.seed(0)
        self.host.env.reset()  # the controller's state as every episode's reset leaves it
        robot = env.robots[0]
        ctrl = robot.controller
        gripper = robot.gripper
        m = env.sim.model._model
        low, high = robot.torque_limits
        return {
            "xml": env.model.get_xml(),
            "mujoco_version": __import__("mujoco").__version__,
            "body_names": [m.body(i).name for i in range(m.nbody)],
            "body_mass": m.body_mass.copy(),
            "body_inertia": m.body_inertia.copy(),
            "body_ipos": m.body_ipos.copy(),
            "body_iquat": m.body_iquat.copy(),
            # LIBERO places its fixtures by writing the compiled model's body poses at reset,
            # drawn from numpy's global RNG (here seeded with 0, as initial state 0 is; the
            # others: `fixture_poses`); the MJCF holds their defaults
            "body_pos": m.body_pos.copy(),
            "body_quat": m.body_quat.copy(),
            # colours as LIBERO's reset leaves them: it hides its visualisation sites (the
            # gripper's, a stove's burner while off) by their alpha in the compiled model
            "geom_rgba": m.geom_rgba.copy(),
            "site_rgba": m.site_rgba.copy(),
            "nq": int(m.nq),
            "nv": int(m.nv),
            "init_states": np.asarray(self.host.init_states, np.float64),
            "settle_steps": SETTLE_STEPS,
            "settle_action": DUMMY_ACTION.astype(np.float64),
            "n_substeps": round(env.control_timestep / env.model_timestep),
            "eef_site": ctrl.eef_name,
            "eef_body": robot.robot_model.eef_name,
            "arm_joints": [m.joint(int(j)).name for j in robot._ref_joint_indexes],
            "arm_actuators": [m.actuator(int(a)).name for a in robot._ref_joint_actuator_indexes],
            "gripper_actuators": list(gripper.actuators),
            "gripper_joints": list(robot.gripper_joints),
            "gripper_speed": float(gripper.speed),
            "gripper_action_after_reset": np.asarray(gripper.current_action, np.float64),
            "kp": np.asarray(ctrl.kp, np.float64),
            "kd": np.asarray(ctrl.kd, np.float64),
            "input_min": np.asarray(ctrl.input_min, np.float64),
            "input_max": np.asarray(ctrl.input_max, np.float64),
            "output_min": np.asarray(ctrl.output_min, np.float64),
            "output_max": np.asarray(ctrl.output_max, np.float64),
            "uncouple_pos_ori": bool(ctrl.uncoupling),
            "nullspace_pose": np.asarray(ctrl.initial_joint, np.float64),
            "torque_low": np.asarray(low, np.float64),
            "torque_high": np.asarray(high, np.float64),
            "goal_ori_after_reset": np.asarray(ctrl.goal_ori, np.float64),
            # what the controller last read, at `reset`: its first step after
            # `set_init_state` reads nothing new (robosuite's `update` runs only after a
            # `run_controller`), so that step's goal and first torques come from these
            "stale_ee_pos": np.asarray(ctrl.ee_pos, np.float64),
            "stale_ee_mat": np.asarray(ctrl.ee_ori_mat, np.float64),
            "stale_jac": np.asarray(ctrl.J_full, np.float64),
            "stale_mass": np.asarray(ctrl.mass_matrix, np.float64),
            "stale_q": np.asarray(ctrl.joint_pos, np.float64),
            "stale_qd": np.asarray(ctrl.joint_vel, np.float64),
            "stale_pending": bool(not ctrl.new_update),
            "check": {
                "interpolator": ctrl.interpolator_pos is None and ctrl.interpolator_ori is None,
                "impedance_mode": ctrl.impedance_mode,
                "use_delta": bool(ctrl.use_delta),
                "use_ori": bool(ctrl.use_ori),
                "position_limits": ctrl.position_limits is None,
                "orientation_limits": ctrl.orientation_limits is None,
            },
        }

    def fixture_poses(self) -> dict[str, np.ndarray]:
        """Every body's pose after LIBERO's reset for each initial state i, numpy's RNG seeded
        with i as the worker's `reset` seeds it: LIBERO draws its fixtures' poses (cabinets,
        stoves, racks: bodies without joints, which an initial state does not hold) at every
        reset, ~1 cm apart from one seed to the next. Only the reset's sampling runs
        (`_reset_internal`, which is the first to draw): a full reset rebuilds the model
        first but draws nothing, so the poses are the same, 500x faster."""
        inner = self.env
        pos, quat = [], []
        for i in range(len(self.host.init_states)):
            np.random.seed(i)
            inner.sim.reset()
            inner._reset_internal()
            m = inner.sim.model._model
            pos.append(m.body_pos.copy())
            quat.append(m.body_quat.copy())
        self._reset(0)  # leave the env as every other method finds it
        return {"fixture_pos": np.stack(pos), "fixture_quat": np.stack(quat)}

    def sampled_states(self, start: int, stop: int) -> dict[str, np.ndarray]:
        """LIBERO's own initial state for each seed in ``start..stop-1`` of the mass-seed
        protocol: the worker's sampled `reset` itself (LIBERO's full reset, numpy seeded with
        the seed: objects in their BDDL regions, fixtures, articulated joints, a failed
        placement retried), before its settle steps. Per seed the flattened ``[time, qpos,
        qvel]`` state and the poses of the fixtures' root bodies (``fixture_ids``: LIBERO's
        reset places them without a joint).

        Only the full reset reproduces LIBERO: re-running its placement on the live
        simulation (`sim.reset` and `_reset_internal`, as this did until 2026-11-29) put an
        object placed on a fixture (``libero_spatial/3``'s second bowl, on the cabinet) where
        the previous draw's state said, 0.9 m above LIBERO's."""
        m = self.env.sim.model._model
        ids = np.array(sorted(m.body(f.root_body).id for f in self.env.fixtures_dict.values()), int)
        draws = [self.drawn_state(seed) for seed in range(start, stop)]
        self._reset(0)  # leave the env as every other method finds it
        states = [d["state"] for d in draws]
        pos = [d["body_pos"][ids] for d in draws]
        quat = [d["body_quat"][ids] for d in draws]
        return {
            "states": np.stack(states),
            "fixture_ids": ids.astype(np.int64),
            "fixture_pos": np.stack(pos),
            "fixture_quat": np.stack(quat),
        }

    def drawn_state(self, seed: int) -> dict[str, np.ndarray]:
        """LIBERO's full reset for seed `seed` of the mass-seed protocol, as the worker's
        sampled `reset` runs it before its settle steps: the flattened ``[time, qpos, qvel]``
        state and every body's pose (what `sampled_states` keeps, per seed)."""
        self.host.start(seed, sampled=True)
        sim = self.env.sim
        m = sim.model._model
        state = np.asarray(sim.get_state().flatten(), np.float64)
        return {"state": state, "body_pos": m.body_pos.copy(), "body_quat": m.body_quat.copy()}

    def body_poses(self, init: int, sampled: bool = False) -> dict[str, np.ndarray]:
        """Every body's pose in the model after the worker's full reset to initial state
        `init` (`sampled`: to the mass-seed protocol's draw for seed `init`): what
        `fixture_poses` and `sampled_states` must reproduce."""
        self._reset(init, sampled)
        m = self.env.sim.model._model
        return {"body_pos": m.body_pos.copy(), "body_quat": m.body_quat.copy()}

    def observation_substep(self, steps: int = 20) -> int:
        """Which physics step of a control step (1-based) robosuite's observation is read
        after: its observables sample on a timer that it advances by the physics step and
        compares with the 20 Hz period in floating point, and the end-effector position it
        returns matches the data one particular physics step left (measured here, and
        required to be the same at every step)."""
        self._reset(0)
        sim = self.env.sim
        m, d = sim.model._model, sim.data._data
        site = m.site(self.env.robots[0].controller.eef_name).id
        seen: list[np.ndarray] = []
        step = sim.step

        def recording_step() -> None:
            step()
            seen.append(d.site_xpos[site].copy())

        sim.step = recording_step
        try:
            found = set()
            rng = np.random.default_rng(0)
            for _ in range(steps):
                seen.clear()
                raw, _, _, _ = self.host.env.step(rng.uniform(-1.0, 1.0, 7))
                match = [k for k, p in enumerate(seen) if np.array_equal(p, raw["robot0_eef_pos"])]
                found.add(match[0] + 1 if match else -1)
        finally:
            sim.step = step
        if len(found) != 1 or -1 in found:
            raise ValueError(f"robosuite's observation follows no one physics step: {found}")
        return found.pop()

    def camera_states(self, init: int, actions: np.ndarray, drawn: int) -> dict[str, np.ndarray]:
        """LIBERO's camera observations (``image``, ``wrist_image``, as the host scene gives
        them) after the reset to initial state `init` and after each of `actions`, and the
        state each was drawn from: ``qpos``, ``qvel`` at the end of physics step `drawn`
        (1-based) of that control step (robosuite renders from the data its observed step
        leaves, whose poses are the previous step's state)."""
        n = round(self.env.control_timestep / self.env.model_timestep)
        seen: list[np.ndarray] = []
        # the class's `step`: LIBERO's reset may build a new simulation object
        sim_class = type(self.env.sim)
        step = sim_class.step

        def recording_step(sim: Any) -> None:
            step(sim)
            seen.append(np.concatenate([sim.data.qpos, sim.data.qvel]))

        out: dict[str, list[np.ndarray]] = {"image": [], "wrist_image": [], "state": []}

        def record(obs: dict[str, np.ndarray]) -> None:
            out["image"].append(obs["image"])
            out["wrist_image"].append(obs["wrist_image"])
            out["state"].append(seen[len(seen) - n + drawn - 1])

        sim_class.step = recording_step
        try:
            obs, _ = self.host.reset(seed=0, options={"init_state": init})
            record(obs)
            for a in np.asarray(actions, np.float64):
                obs, *_ = self.host.step(a)
                record(obs)
        finally:
            sim_class.step = step
        nq = self.env.sim.model._model.nq
        state = np.stack(out.pop("state"))
        return {
            **{k: np.stack(v) for k, v in out.items()},
            "qpos": state[:, :nq],
            "qvel": state[:, nq:],
        }

    def goal(self) -> list[dict[str, Any]]:
        """The task's BDDL goal as data the mirror evaluates in JAX (`goal_atoms`)."""
        return goal_atoms(self.env)

    def check_success(self, states: np.ndarray) -> np.ndarray:
        """LIBERO's goal (`_check_success`) at each flattened ``[time, qpos, qvel]`` state,
        after a forward pass (contacts and poses of that state)."""
        sim = self.env.sim
        out = []
        for state in np.asarray(states, np.float64):
            sim.set_state_from_flattened(state)
            sim.forward()
            out.append(bool(self.env._check_success()))
        return np.array(out)

    def rollout(
        self, init: int, actions: np.ndarray, sampled: bool = False
    ) -> dict[str, np.ndarray]:
        """Reset to initial state `init` (`sampled`: the mass-seed protocol's draw for seed
        `init`) and LIBERO's settle steps, then play `actions` ((T, 7)); per step 0..T: qpos,
        qvel, the lerobot state, the ``expert`` entry, the success predicate."""
        self._reset(init, sampled)
        sim = self.env.sim
        qpos, qvel, state, expert, success = [], [], [], [], []

        def record(done: bool) -> None:
            qpos.append(np.array(sim.data.qpos))
            qvel.append(np.array(sim.data.qvel))
            raw = self.env._get_observations()
            obs = self.host._obs(raw)
            state.append(obs["state"])
            expert.append(obs["expert"])
            success.append(done)

        record(False)
        for a in np.asarray(actions, np.float64):
            self.host.env.step(a)
            record(bool(self.env._check_success()))
        return {
            "qpos": np.stack(qpos),
            "qvel": np.stack(qvel),
            "state": np.stack(state),
            "expert": np.stack(expert),
            "success": np.array(success),
        }


def goal_atoms(env: Any) -> list[dict[str, Any]]:
    """LIBERO env `env`'s BDDL goal (a conjunction) as data the mirror evaluates in JAX: one
    dict per atom, with what LIBERO's predicate reads (see `openral_mjx.benchmarks.libero.
    mirror.goal`). Joint thresholds are found by bisecting LIBERO's own methods."""
    goal = env.parsed_problem["goal_state"]
    return [_atom(env, atom[0].lower(), atom[1:]) for atom in goal]


def closes(atom: dict[str, Any]) -> bool:
    """Whether a joint atom drives its joint back to rest (close, turn off: the threshold at
    the joint's zero) rather than away from it (open, turn on)."""
    return abs(float(atom["threshold"][0])) <= 0.01


def expert_atoms(atoms: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The goal's atoms `libero-expert` plays, in the order it plays them (at most
    `EXPERT_ATOMS`): joint atoms that open or turn on first, then the pick-and-place atoms,
    then the joint atoms that close or turn off (a drawer is opened before a bowl goes in and
    shut after)."""
    joints = [a for a in atoms if a["kind"] == "joints"]
    picks = [a for a in atoms if a["kind"] in PICK_KINDS]
    ordered = [a for a in joints if not closes(a)] + picks + [a for a in joints if closes(a)]
    return ordered[:EXPERT_ATOMS]


def moving_body(model: Any, joint: str) -> str:
    """The name of the body `joint` moves (`model` a `mujoco.MjModel`)."""
    return model.body(int(model.joint(joint).bodyid[0])).name


def expert_ids(atoms: list[dict[str, Any]], model: Any, index: Any) -> list[tuple[int, int, int]]:
    """Per atom of `expert_atoms`, what its ``expert`` row reads (`expert_entry`): (moved
    body, target body, -1) for a pick-and-place atom, (moving body, moving body, the joint's
    qpos address) for a joint atom; bodies as `index(name)` places them in the caller's
    arrays, `model` a `mujoco.MjModel` of the task."""
    ids = []
    for a in expert_atoms(atoms):
        if a["kind"] == "joints":
            body = index(moving_body(model, a["joints"][0]))
            ids.append((body, body, int(model.joint(a["joints"][0]).qposadr[0])))
        else:
            ids.append((index(a["obj"]), index(a.get("target") or a["site_body"]), -1))
    return ids


def expert_entry(
    positions: Any, quats: Any, qpos: Any, ids: list[tuple[int, int, int]], xp: Any = np
) -> Any:
    """The ``expert`` entry from body `positions` (n, 3), `quats` (n, 4) and `qpos` (numpy, or
    jax.numpy as `xp`), per `expert_ids` row; zeros for the atoms the goal lacks."""
    parts = []
    for obj, target, adr in ids:
        middle = (
            positions[target] if adr < 0 else xp.concatenate([qpos[adr : adr + 1], xp.zeros(2)])
        )
        parts.append(xp.concatenate([positions[obj], middle, quats[target]]))
    parts += [xp.zeros(ATOM_SIZE, xp.float32)] * (EXPERT_ATOMS - len(ids))
    return xp.concatenate([xp.asarray(p, xp.float32) for p in parts])


def _body(env: Any, name: str) -> str:
    m = env.sim.model._model
    return m.body(int(env.obj_body_id[name])).name


def _contact_geoms(env: Any, name: str) -> list[str]:
    """The geoms robosuite's `check_contact` reads for object `name`, those that can
    collide (a geom that cannot is never in MuJoCo's contact list)."""
    m = env.sim.model._model
    names = env.get_object(name).contact_geoms
    return [g for g in names if m.geom_contype[m.geom(g).id] or m.geom_conaffinity[m.geom(g).id]]


def _site(env: Any, name: str) -> dict[str, Any]:
    m = env.sim.model._model
    site = m.site(name)
    region = env.object_sites_dict[name]
    return {
        "site_body": m.body(int(site.bodyid[0])).name,
        "site_pos": [float(v) for v in site.pos],
        "site_quat": [float(v) for v in site.quat],
        "size": [float(v) for v in region.size],
    }


def _atom(env: Any, predicate: str, args: list[str]) -> dict[str, Any]:
    states = env.object_states_dict
    if predicate == "on":
        obj, target = args
        if states[target].object_state_type != "site":
            return {
                "kind": "on_object",
                "obj": _body(env, obj),
                "target": _body(env, target),
                "contact": [_contact_geoms(env, target), _contact_geoms(env, obj)],
            }
        region = env.object_sites_dict[target]
        if not hasattr(region, "under"):
            return {"kind": "true"}
        parent = states[target].parent_name
        has_parent = env.get_object(parent) is not None
        return {
            "kind": "on_site",
            "obj": _body(env, obj),
            **_site(env, target),
            "contact": [_contact_geoms(env, parent), _contact_geoms(env, obj)]
            if has_parent
            else [],
        }
    if predicate == "in":
        obj, target = args
        if states[target].object_state_type != "site":
            raise ValueError(f"In({obj}, {target}): only regions (sites) hold objects")
        return {"kind": "in_site", "obj": _body(env, obj), **_site(env, target)}
    if predicate in ("open", "close", "turnon", "turnoff"):
        (name,) = args
        state = states[name]
        if state.object_state_type == "site":
            joints = env.object_sites_dict[name].joints
            owner = env.get_object(state.parent_name)
        else:
            joints = env.get_object(name).joints
            owner = env.get_object(name)
        method = getattr(owner, _METHODS[predicate])
        m = env.sim.model._model
        limits = [m.joint(j).range for j in joints]
        thresholds = [_threshold(method, lo, hi) for lo, hi in limits]
        return {
            "kind": "joints",
            "joints": list(joints),
            "threshold": [t for t, _, _ in thresholds],
            "above": [a for _, a, _ in thresholds],
            "inclusive": [i for _, _, i in thresholds],
            "all": predicate in ("close", "turnoff"),  # LIBERO: every joint; else any
        }
    raise ValueError(f"LIBERO predicate {predicate!r} is not mirrored")


def _threshold(method: Any, lo: float, hi: float) -> tuple[float, bool, bool]:
    """(T, above, inclusive) with ``method(q) == (q > T)`` (above; ``q >= T`` if inclusive)
    or ``(q < T)`` (``q <= T``) on the joint's range widened by 1: LIBERO's articulation
    predicates are one-sided thresholds on round numbers (found to 12 decimals)."""
    grid = np.linspace(lo - 1.0, hi + 1.0, 4001)
    values = np.array([bool(method(q)) for q in grid])
    flips = np.flatnonzero(values[1:] != values[:-1])
    if len(flips) != 1:
        raise ValueError(f"{method.__qualname__} is not a single threshold on [{lo}, {hi}]")
    a, b = grid[flips[0]], grid[flips[0] + 1]
    above = bool(values[-1])
    for _ in range(60):
        mid = 0.5 * (a + b)
        if bool(method(mid)) == above:
            b = mid
        else:
            a = mid
    t = round(0.5 * (a + b), 12)
    return t, above, bool(method(t)) == above
