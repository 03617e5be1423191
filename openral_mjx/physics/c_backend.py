"""MuJoCo C physics inside the jitted loop, through one host callback per batched control step.

The whole batch crosses into `mujoco.rollout.Rollout` (a persistent C++ thread pool) in a single
`jax.pure_callback`; vmap hands the callback the full batch (`vmap_method="broadcast_all"`).
The float64 MuJoCo state travels through JAX losslessly as its raw bits (`uint32` pairs), so
the simulation is exactly MuJoCo C's whatever JAX's default float width. Body and site poses
come back as `framepos`/`framequat` sensors added to this backend's private copy of the model,
among them the poses of the bodies that ray-cast sensors see; the rays are cast in JAX from
those poses, as on every backend (`raycast`). RGB cameras (`RgbSpec`) are drawn by MuJoCo's own
OpenGL renderer in the same callback, per env, from the state the step ends in (`c_render`).
"""

from __future__ import annotations

import atexit
import copy
import functools
import os
import threading
import weakref
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import rollout

from openral_mjx.core.errors import ConfigError
from openral_mjx.physics.base import (
    PhysicsBackend,
    PhysicsState,
    Quantities,
    QuantitySpec,
    check_fields,
)
from openral_mjx.physics.c_render import HostCameras
from openral_mjx.physics.cameras import RgbSpec, SensorSpec
from openral_mjx.physics.contact_sensors import add_contact_sensors

_FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS
# Memory the per-env model copies may take (envs with their own model fields): tabletop_push's
# model is ~20 kB (every env of a batch gets its copy), MetaWorld's ~19 MB (13 at a time).
COPY_BUDGET = 256 * 2**20
_CTRL = int(mujoco.mjtState.mjSTATE_CTRL)
_CTRL_MOCAP = (
    _CTRL | int(mujoco.mjtState.mjSTATE_MOCAP_POS) | int(mujoco.mjtState.mjSTATE_MOCAP_QUAT)
)
_LIVE: weakref.WeakSet[CBackend] = weakref.WeakSet()


@atexit.register
def _close_all() -> None:
    """Stop rollout thread pools before interpreter shutdown (avoids a GIL fault at exit)."""
    for backend in list(_LIVE):
        backend.close()


def _with_lead(out: tuple, lead: tuple[int, ...]) -> tuple:
    """Host results (n, ...) (a dict: each entry) reshaped to vmap's batch shape `lead`."""
    shape = lambda o: o.reshape(lead + o.shape[1:])  # noqa: E731
    return tuple(
        {k: shape(v) for k, v in o.items()} if isinstance(o, dict) else shape(o) for o in out
    )


def _exact_fields(value: np.ndarray, nominal: np.ndarray) -> np.ndarray:
    """`value` (per env, float32 values as float64) with each entry that equals `nominal`'s
    entry rounded to float32 replaced by the float64 `nominal` entry.

    MetaWorld's plate rests on its channel at distance exactly 0; with the channel's body
    position rounded to float32 (3e-10 m lower) the same push moved it 0.055 m/s slower
    after one step, and the scripted expert succeeded 37 steps later than on MetaWorld."""
    rounded = nominal.astype(np.float32).astype(np.float64)
    return np.where(value == rounded, nominal, value)


def default_threads() -> int:
    """All cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - non-Linux
        return os.cpu_count() or 1


class CBackend(PhysicsBackend):
    """MuJoCo's C engine (float64), multithreaded over the batch with `mujoco.rollout`.

    `settings.threads` worker threads step the batch (default: all available cores). Envs
    with their own model fields (`PhysicsState.fields`) step on per-env copies of the model,
    whose fields are written before each batched step.
    """

    name = "c"
    layout_invariant = True  # per-env C physics outside XLA; see docs/cli.md's determinism table

    def _rendered(self, sensors: tuple[SensorSpec, ...]) -> frozenset[str]:
        """Every RGB camera, drawn by MuJoCo's renderer (`c_render`); depth is ray cast."""
        self._rgb = tuple(s for s in sensors if isinstance(s, RgbSpec))
        return frozenset(s.key for s in self._rgb)

    def _setup(self, spec: mujoco.MjSpec) -> None:
        self.threads = self.settings.threads or default_threads()
        self._model = self._model_with_pose_sensors(spec, self.quantity_spec)
        m = self._model
        self.nq, self.nv, self.nu = m.nq, m.nv, m.nu
        self.nstate = mujoco.mj_stateSize(m, _FULL)
        # Offsets into the FULLPHYSICS state vector: components are stored in bit order.
        full = int(_FULL)
        self._off_qpos = mujoco.mj_stateSize(m, full & (int(mujoco.mjtState.mjSTATE_QPOS) - 1))
        self._off_qvel = self._off_qpos + self.nq
        self._nsens = m.nsensordata
        self._pool: rollout.Rollout | None = None
        self._datas: list[mujoco.MjData] = []
        self._env_models: list[mujoco.MjModel] = []
        self._model_bytes = mujoco.mj_sizeModel(m)  # what one per-env copy takes
        self._written: dict[str, np.ndarray] = {}  # per copy: the field values written into it
        self._lock = threading.Lock()
        self.cameras = HostCameras(m, self._rgb) if self._rgb else None
        _LIVE.add(self)

    def _model_with_pose_sensors(
        self, spec: mujoco.MjSpec, quantities: QuantitySpec
    ) -> mujoco.MjModel:
        """Compile a copy whose only sensors are the pose readouts (in a fixed order)."""
        s = spec.copy()
        for sensor in list(s.sensors):
            s.delete(sensor)
        for name in quantities.bodies:
            for kind in (mujoco.mjtSensor.mjSENS_FRAMEPOS, mujoco.mjtSensor.mjSENS_FRAMEQUAT):
                s.add_sensor(type=kind, objtype=mujoco.mjtObj.mjOBJ_XBODY, objname=name)
        for name in quantities.sites:
            s.add_sensor(
                type=mujoco.mjtSensor.mjSENS_FRAMEPOS,
                objtype=mujoco.mjtObj.mjOBJ_SITE,
                objname=name,
            )
        for name in quantities.geoms:
            for kind in (mujoco.mjtSensor.mjSENS_FRAMEPOS, mujoco.mjtSensor.mjSENS_FRAMEQUAT):
                s.add_sensor(type=kind, objtype=mujoco.mjtObj.mjOBJ_GEOM, objname=name)
        for b in self.sensor_bodies:
            for kind in (mujoco.mjtSensor.mjSENS_FRAMEPOS, mujoco.mjtSensor.mjSENS_FRAMEQUAT):
                s.add_sensor(
                    type=kind, objtype=mujoco.mjtObj.mjOBJ_XBODY, objname=self.mj_model.body(b).name
                )
        if quantities.contacts and quantities.poses_after_step:
            raise ConfigError(
                "contact quantities read the step's own collision: no poses_after_step"
            )
        self._contact_slices = add_contact_sensors(s, self.mj_model, quantities.contacts)
        return s.compile()

    # ---- host side (numpy, float64) -------------------------------------------------------

    def _ensure_pool(self) -> rollout.Rollout:
        if self._pool is None:
            self._pool = rollout.Rollout(nthread=self.threads)
            self._datas = [mujoco.MjData(self._model) for _ in range(self.threads)]
        return self._pool

    def close(self) -> None:
        """Shut the thread pools down (they are re-created on next use)."""
        if self._pool is not None:
            self._pool.close()
            self._pool = None
        if self.cameras is not None:
            self.cameras.close()

    def _readout(
        self, states: np.ndarray, sens: np.ndarray, ok: np.ndarray, images: dict[str, np.ndarray]
    ) -> tuple:
        nb, ns = len(self.quantity_spec.bodies), len(self.quantity_spec.sites)
        ng, nr = len(self.quantity_spec.geoms), len(self.sensor_bodies)
        n = len(sens)
        body = sens[:, : 7 * nb].reshape(n, nb, 7)
        site = sens[:, 7 * nb : 7 * nb + 3 * ns].reshape(n, ns, 3)
        at = 7 * nb + 3 * ns
        geom = sens[:, at : at + 7 * ng].reshape(n, ng, 7)
        at += 7 * ng
        seen = sens[:, at : at + 7 * nr].reshape(n, nr, 7)
        at += 7 * nr
        # the contact sensors follow, one float each: a pair touches where any counts a match
        touching = np.zeros((n, len(self._contact_slices)), bool)
        for i, (a, b) in enumerate(self._contact_slices):
            base = at - self._contact_slices[0][0]
            touching[:, i] = sens[:, base + a : base + b].sum(axis=1) > 0
        qpos = states[:, self._off_qpos : self._off_qpos + self.nq]
        qvel = states[:, self._off_qvel : self._off_qvel + self.nv]
        ok = ok & np.isfinite(states).all(axis=1) & np.isfinite(sens).all(axis=1)
        f32 = np.float32
        return (
            states.view(np.uint32).copy(),
            qpos.astype(f32),
            qvel.astype(f32),
            body[:, :, :3].astype(f32),
            body[:, :, 3:].astype(f32),
            site.astype(f32),
            geom[:, :, :3].astype(f32),
            geom[:, :, 3:].astype(f32),
            seen[:, :, :3].astype(f32),
            seen[:, :, 3:].astype(f32),
            touching,
            ok,
            images,
        )

    def _models(self, n: int, names: tuple[str, ...], values: tuple) -> list[mujoco.MjModel]:
        """`n` model copies with env i's `values` of fields `names` written into copy i.

        Copies are kept and reused. Each remembers what was written into it, so only the rows
        whose values changed are written again (in a batch of running episodes: none), and a
        field no longer named goes back to the model's own value. A model with meshes copies
        its mesh data too (MetaWorld's: ~19 MB), so callers step envs with their own fields in
        slices of `_slice` envs, as many as `COPY_BUDGET` holds."""
        while len(self._env_models) < n:
            self._env_models.append(copy.copy(self._model))
        models = self._env_models[:n]
        for name in set(self._written) - set(names):  # restore what this call leaves alone
            nominal = getattr(self._model, name)
            for m in self._env_models:
                getattr(m, name)[:] = nominal
            del self._written[name]
        for name, value in zip(names, values, strict=True):
            nominal = getattr(self._model, name)
            value = np.asarray(value, np.float64).reshape((n, *nominal.shape))
            # Values come through JAX as float32: one that is the model's own value rounded
            # keeps the float64 original. A rounded position can move a resting contact off
            # its exact zero distance and change how an object slides (`_exact_fields`).
            value = _exact_fields(value, nominal)
            written = self._written.get(name)
            if written is None or len(written) < len(self._env_models):
                grown = np.full((len(self._env_models), *nominal.shape), np.nan)  # NaN: not known
                if written is not None:
                    grown[: len(written)] = written
                written = self._written[name] = grown
            changed = np.flatnonzero((value != written[:n]).reshape(n, -1).any(axis=1))
            for i in changed:
                getattr(models[i], name)[:] = value[i]
            written[changed] = value[changed]
        return models

    @property
    def _slice(self) -> int:
        """Envs per `rollout` call when each has its own model: as many model copies as
        `COPY_BUDGET` bytes hold, and at least a few per thread."""
        return max(4 * self.threads, COPY_BUDGET // max(1, self._model_bytes))

    def _host_init(
        self, names: tuple[str, ...], qpos: np.ndarray, qvel: np.ndarray, *values
    ) -> tuple:
        lead = qpos.shape[:-1]
        qpos = np.asarray(qpos, np.float64).reshape(-1, self.nq)
        qvel = np.asarray(qvel, np.float64).reshape(-1, self.nv)
        n = qpos.shape[0]
        # one row per env, also for an unbatched call (then the fields have no lead axis)
        values = tuple(
            np.asarray(v).reshape((n, *getattr(self._model, k).shape))
            for k, v in zip(names, values, strict=True)
        )
        d = mujoco.MjData(self._model)
        states = np.empty((n, self.nstate))
        sens = np.empty((n, self._nsens))
        images = self._no_images(n)
        for i in range(n):  # reset only, once per chunk: not on the stepping hot path
            m = self._model
            if names:
                with self._lock:
                    m = self._models(1, names, tuple(v[i : i + 1] for v in values))[0]
            mujoco.mj_resetData(m, d)
            d.qpos[:], d.qvel[:] = qpos[i], qvel[i]
            mujoco.mj_forward(m, d)
            mujoco.mj_getState(m, d, states[i], _FULL)
            sens[i] = d.sensordata
            if self.cameras is not None:
                for key, image in self.cameras.render(states[i : i + 1], [m]).items():
                    images[key][i] = image[0]
        out = self._readout(states, sens, np.ones(n, bool), images)
        return _with_lead(out, lead)

    def _no_images(self, n: int) -> dict[str, np.ndarray]:
        """Room for `n` envs' images of every RGB camera (none without cameras)."""
        return {s.key: np.zeros((n, s.height, s.width, 3), np.uint8) for s in self._rgb}

    def _host_step(
        self,
        names: tuple[str, ...],
        mocap: bool,
        render: bool,
        bits: np.ndarray,
        ctrl: np.ndarray,
        *rest,
    ) -> tuple:
        lead = ctrl.shape[:-1]
        states = np.ascontiguousarray(bits, np.uint32).reshape(-1, 2 * self.nstate)
        states = states.view(np.float64)
        n = states.shape[0]
        control = [np.asarray(ctrl, np.float64).reshape(n, self.nu)]
        if mocap:
            control += [np.asarray(r, np.float64).reshape(n, -1) for r in rest[:2]]
            rest = rest[2:]
        control = np.nan_to_num(np.concatenate(control, axis=1)[:, None, :])
        spec = _CTRL_MOCAP if mocap else _CTRL
        cameras = self.cameras if render else None
        images = self._no_images(n) if cameras is not None else {}
        with self._lock:
            pool = self._ensure_pool()
            if not names:
                out, sens = pool.rollout(
                    self._model,
                    self._datas,
                    states,
                    control,
                    control_spec=spec,
                    nstep=self.n_substeps,
                )
                last, sens = out[:, -1], sens[:, -1]
                if self.quantity_spec.poses_after_step:
                    sens = self._poses_after(self._model, last)
                if cameras is not None:
                    images = cameras.render(last)
            else:  # per-env models, a slice of envs at a time (see `_models`)
                last = np.empty_like(states)
                sens = np.empty((n, self._nsens))
                values = [np.asarray(v).reshape(n, -1) for v in rest]
                for a in range(0, n, self._slice):
                    b = min(n, a + self._slice)
                    models = self._models(b - a, names, tuple(v[a:b] for v in values))
                    out, s_out = pool.rollout(
                        models,
                        self._datas,
                        states[a:b],
                        control[a:b],
                        control_spec=spec,
                        nstep=self.n_substeps,
                    )
                    last[a:b], sens[a:b] = out[:, -1], s_out[:, -1]
                    if self.quantity_spec.poses_after_step:
                        sens[a:b] = self._poses_after(models, last[a:b])
                    if cameras is not None:
                        for key, image in cameras.render(last[a:b], models).items():
                            images[key][a:b] = image
        last = np.ascontiguousarray(last)
        # MuJoCo resets a state it finds unstable (time goes back to 0): that env diverged.
        expected = states[:, 0] + self.n_substeps * self._model.opt.timestep
        ok = np.abs(last[:, 0] - expected) < 0.5 * self._model.opt.timestep
        res = self._readout(last, np.ascontiguousarray(sens), ok, images)
        return _with_lead(res, lead)

    def _poses_after(
        self, models: mujoco.MjModel | list[mujoco.MjModel], states: np.ndarray
    ) -> np.ndarray:
        """The pose sensors of `states` themselves (kinematics, then the position sensors):
        `rollout`'s sensor data, like `mj_step`'s, is computed before the last integration."""
        d = self._datas[0]  # the pool is idle here (under `_lock`)
        out = np.empty((len(states), self._nsens))
        for i, state in enumerate(states):
            m = models[i] if isinstance(models, list) else models
            mujoco.mj_setState(m, d, np.ascontiguousarray(state), _FULL)
            mujoco.mj_kinematics(m, d)
            mujoco.mj_sensorPos(m, d)
            out[i] = d.sensordata
        return out

    # ---- JAX side --------------------------------------------------------------------------

    def _result_shapes(self, lead: tuple[int, ...], images: bool = True) -> tuple:
        nb, ns = len(self.quantity_spec.bodies), len(self.quantity_spec.sites)
        ng, nr = len(self.quantity_spec.geoms), len(self.sensor_bodies)
        f32 = jnp.float32
        sd = jax.ShapeDtypeStruct
        return (
            sd((*lead, 2 * self.nstate), jnp.uint32),
            sd((*lead, self.nq), f32),
            sd((*lead, self.nv), f32),
            sd((*lead, nb, 3), f32),
            sd((*lead, nb, 4), f32),
            sd((*lead, ns, 3), f32),
            sd((*lead, ng, 3), f32),
            sd((*lead, ng, 4), f32),
            sd((*lead, nr, 3), f32),
            sd((*lead, nr, 4), f32),
            sd((*lead, len(self.quantity_spec.contacts)), jnp.bool_),
            sd((*lead,), jnp.bool_),
            {s.key: sd((*lead, s.height, s.width, 3), jnp.uint8) for s in self._rgb}
            if images
            else {},
        )

    def _pack(
        self, out: Any, fields: dict[str, jax.Array], kept: dict[str, jax.Array] | None = None
    ) -> PhysicsState:
        """The state from a callback's results; RGB images from the results in [0, 1], or
        `kept` (a step that drew none keeps the previous state's)."""
        bits, qpos, qvel, bpos, bquat, spos, gpos, gquat, rpos, rquat, touching, ok, images = out
        sensors = self.read_sensors_of(rpos, rquat, fields)
        sensors.update({k: v.astype(jnp.float32) / 255.0 for k, v in images.items()})
        sensors.update(kept or {})
        q = Quantities(
            qpos=qpos,
            qvel=qvel,
            body_pos=bpos,
            body_quat=bquat,
            site_pos=spos,
            geom_pos=gpos,
            geom_quat=gquat,
            ok=ok,
            sensors=sensors,
            contacts=touching,
        )
        return PhysicsState(data=bits, quantities=q, fields=fields)

    def init(
        self, qpos: jax.Array, qvel: jax.Array, fields: dict[str, jax.Array] | None = None
    ) -> PhysicsState:
        fields = dict(fields or {})
        check_fields(fields)
        names = tuple(sorted(fields))
        out = jax.pure_callback(
            functools.partial(self._host_init, names),
            self._result_shapes(()),
            qpos,
            qvel,
            *(fields[k] for k in names),
            vmap_method="broadcast_all",
        )
        return self._pack(out, fields)

    def step(
        self,
        state: PhysicsState,
        ctrl: jax.Array,
        mocap: tuple[jax.Array, jax.Array] | None = None,
        render: bool = True,
    ) -> PhysicsState:
        names = tuple(sorted(state.fields))
        extra = [] if mocap is None else [m.astype(jnp.float32) for m in mocap]
        out = jax.pure_callback(
            functools.partial(self._host_step, names, mocap is not None, render),
            self._result_shapes((), images=render),
            state.data,
            ctrl.astype(jnp.float32),
            *extra,
            *(state.fields[k] for k in names),
            vmap_method="broadcast_all",
        )
        kept = {} if render else {s.key: state.quantities.sensors[s.key] for s in self._rgb}
        new = self._pack(out, state.fields, kept)
        q = new.quantities
        return new.replace(quantities=q.replace(ok=q.ok & state.quantities.ok))

    @property
    def host_model(self) -> mujoco.MjModel:
        """The model MuJoCo C steps: the scene plus this backend's pose sensors."""
        return self._model

    def _candidate_devices(self) -> list[jax.Device]:
        """The host CPU alone: the physics is on the host (one thread pool), so the loop around
        it stays there too rather than bouncing every control step through an accelerator."""
        return [jax.devices("cpu")[0]]

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "threads": self.threads}
