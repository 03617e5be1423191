"""Per-env randomised factors (physics, control, sensing), sampled from each seed at reset.

``--randomize friction=0.3:1.2 mass=0.5x:2x delay=0:3`` wraps a scene in `Randomized` (the
factors and their ranges: `factor_ranges`). Each factor's value is drawn uniformly from its
range with a key folded from the episode's reset key and the factor's name, so seed s always
gets the same values, adding a factor leaves the others' values alone, and the initial state
(drawn from the reset key itself) is the nominal run's: a randomised run is paired with the
nominal one seed by seed. Values are constant within an episode and recorded as episode
factors, so the report's breakdown and plots show success against each of them.

Physics factors become per-env model fields (`PhysicsState.fields`: a batched `mjx.Model` on
`mjx`/`warp`, per-env model copies on `c`). A range written ``LOWx:HIGHx`` multiplies the
model's own values (recorded as ``NAME_scale``); a plain range sets them. Control factors act
on the policy's action, sensing factors on the observation the policy reads; the scene's own
logic (success, frame stacking) sees the true state. Camera factors move the observed cameras
through their per-env `cam_pos`/`cam_quat` (ray cast on every backend, rendered on `warp`);
`light` sets (or, ``LOWx:HIGHx``, scales) the diffuse colour of the scene's lights, each
channel, in the RGB images `warp` renders (the headlight, baked into MuJoCo-Warp's kernel,
stays as it is). The reset's images are drawn again from the moved cameras and lights.

MuJoCo C takes the inertia of a "simple" body (a free object, a lone slider) from `dof_M0`,
which `mj_setConst` derives from masses and armatures at compile time, so a mass or armature
change rewrites it too (MJX computes it from the mass). The other derived constants
(`body_invweight0`, `dof_invweight0`, which scale constraint softness) keep their nominal
values, as in MuJoCo Playground's randomisation; every backend's per-env model agrees on this.
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.rotations import quat_mul
from openral_mjx.scenes.base import RandomizationTargets, Scene, State
from openral_mjx.scenes.factor_ranges import (
    FACTORS,
    MAX_DELAY,
    FactorRange,
    available_factors,
    parse_factors,
)
from openral_mjx.scenes.wrapper import SceneWrapper

INFO_KEY = "randomization"

CAMERA_FACTORS = ("camera_pos", "camera_rot")
# Factors that change what the reset's images show: they are drawn again with the env's fields.
IMAGE_FACTORS = (*CAMERA_FACTORS, "light")


def _salt(name: str) -> int:
    return zlib.crc32(name.encode()) & 0x7FFFFFFF


def _obs_index(layout: Mapping[str, tuple[int, int]], names: Sequence[str]) -> np.ndarray:
    return np.concatenate(
        [np.arange(layout[n][0], layout[n][0] + layout[n][1]) for n in names] or [[]]
    ).astype(np.int32)


class Randomized(SceneWrapper):
    """`scene` with `factors` drawn per seed at reset (see the module docstring).

    Everything else (model, backend, options, scripted policies, videos) is the scene's own,
    forwarded by `SceneWrapper`; what reads a state reads it as the scene knows it.
    """

    def __init__(self, scene: Scene, factors: Sequence[FactorRange]) -> None:
        super().__init__(scene)
        self.factors = tuple(factors)
        if not self.factors:
            raise ConfigError("Randomized needs at least one factor")
        targets = scene.randomization_targets()
        can = available_factors(scene)
        for f in self.factors:
            if f.name not in can:
                raise ConfigError(
                    f"scene {scene.name!r} cannot randomise {f.name!r} ({FACTORS[f.name].help}); "
                    f"valid: {', '.join(can) or '(none: it runs outside JAX)'}"
                )
        assert targets is not None
        self.targets: RandomizationTargets = targets

        m = scene.mj_model
        self._fields = self._field_writers(m, targets)
        low, high = (np.asarray(b, np.float32) for b in scene.action_bounds())
        if "action_noise" in self._names and not np.all(np.isfinite(high - low)):
            raise ConfigError(f"scene {scene.name!r}: action_noise needs finite action bounds")
        self._action_span = jnp.asarray(high - low)
        layout = scene.obs_layout
        flat = isinstance(scene.observation_spec, jax.ShapeDtypeStruct)
        sensing = {"joint_noise", "object_noise", "depth_noise", "depth_dropout"}
        if sensing & set(self._names) and not flat:
            raise ConfigError(f"scene {scene.name!r}: observation noise needs a flat observation")
        self._joint_idx = _obs_index(layout, targets.joint_obs)
        self._object_idx = _obs_index(layout, targets.object_obs)
        names = [n for n, _ in targets.range_obs]
        self._range_idx = _obs_index(layout, names)
        self._range_max = np.concatenate(
            [np.full(layout[n][1], r, np.float32) for n, r in targets.range_obs] or [[]]
        ).astype(np.float32)

    @property
    def _names(self) -> list[str]:
        return [f.name for f in self.factors]

    def _factor(self, name: str) -> FactorRange | None:
        return next((f for f in self.factors if f.name == name), None)

    # ---- model fields ---------------------------------------------------------------------

    def _field_writers(self, m: mujoco.MjModel, t: RandomizationTargets) -> dict[str, Any]:
        """Per physics factor: the ids it writes (checked against the model)."""
        ids: dict[str, Any] = {}
        if self._factor("friction"):
            ids["friction"] = np.asarray(t.contact_geoms)
        if self._factor("mass"):
            ids["mass"] = np.asarray(t.object_bodies)
        if self._factor("kp"):
            act = np.asarray(t.arm_actuators)
            servo = (
                (m.actuator_gaintype[act] == mujoco.mjtGain.mjGAIN_FIXED)
                & (m.actuator_biastype[act] == mujoco.mjtBias.mjBIAS_AFFINE)
                & np.isclose(m.actuator_biasprm[act, 1], -m.actuator_gainprm[act, 0])
            )
            if not servo.all():
                bad = [m.actuator(int(a)).name or int(a) for a in act[~servo]]
                raise ConfigError(f"kp needs position servos; actuators {bad} are not")
            ids["kp"] = act
        if self._factor("damping") or self._factor("armature"):
            ids["dofs"] = np.asarray(t.arm_dofs)
        touched = np.zeros(m.nv, bool)
        if "mass" in ids:
            touched |= np.isin(m.dof_bodyid, ids["mass"])
        if self._factor("armature"):
            touched[ids["dofs"]] = True
        simple = np.flatnonzero(touched & (m.body_simple[m.dof_bodyid] != 0))
        if simple.size:
            ids["simple_dofs"] = simple
        return ids

    def _apply_fields(
        self, fields: dict[str, jax.Array], values: dict[str, jax.Array]
    ) -> dict[str, jax.Array]:
        m = self.inner.mj_model
        base, fields = fields, dict(fields)

        def field(name: str) -> jax.Array:
            """The value before randomisation: the scene's per-env value, or the model's."""
            return base.get(name, jnp.asarray(getattr(m, name), jnp.float32))

        def scaled(f: FactorRange, nominal: jax.Array) -> jax.Array:
            v = values[f.name]
            return nominal * v if f.relative else jnp.broadcast_to(v, nominal.shape)

        if f := self._factor("friction"):
            g = self._fields["friction"]
            fr = field("geom_friction")
            fields["geom_friction"] = fr.at[g, 0].set(scaled(f, fr[g, 0]))
        if f := self._factor("mass"):
            b = self._fields["mass"]
            mass = field("body_mass")
            new = scaled(f, mass[b])
            ratio = new / mass[b]
            fields["body_mass"] = mass.at[b].set(new)
            inertia = field("body_inertia")
            fields["body_inertia"] = inertia.at[b].set(inertia[b] * ratio[:, None])
        if f := self._factor("kp"):
            a = self._fields["kp"]
            gain, bias = field("actuator_gainprm"), field("actuator_biasprm")
            kp = scaled(f, gain[a, 0])
            fields["actuator_gainprm"] = gain.at[a, 0].set(kp)
            fields["actuator_biasprm"] = bias.at[a, 1].set(-kp)
        for name, model_field in (("damping", "dof_damping"), ("armature", "dof_armature")):
            if f := self._factor(name):
                d = self._fields["dofs"]
                nominal = field(model_field)
                fields[model_field] = nominal.at[d].set(scaled(f, nominal[d]))
        cams = np.asarray(self.targets.cameras, np.int64)
        if (f := self._factor("camera_pos")) and cams.size:
            pos = field("cam_pos")
            step = values[f.name] * self._directions(values, "camera_pos", cams.size)
            fields["cam_pos"] = pos.at[cams].set(pos[cams] + step)
        if (f := self._factor("camera_rot")) and cams.size:
            quat = field("cam_quat")
            axes = self._directions(values, "camera_rot", cams.size)
            half = 0.5 * values[f.name]
            turn = jnp.concatenate(
                [jnp.full((cams.size, 1), jnp.cos(half)), jnp.sin(half) * axes], axis=1
            )
            fields["cam_quat"] = quat.at[cams].set(quat_mul(quat[cams], turn))
        if f := self._factor("light"):
            lights = np.asarray(self.targets.lights, np.int64)
            diffuse = field("light_diffuse")
            fields["light_diffuse"] = diffuse.at[lights].set(scaled(f, diffuse[lights]))
        simple = self._fields.get("simple_dofs")
        if simple is not None:
            # MuJoCo C takes the inertia of a "simple" body's dofs from `dof_M0` (computed at
            # compile time, armature included), not from its mass: keep it in step.
            ratio = jnp.ones(m.nbody, jnp.float32)
            if "mass" in self._fields:
                b = self._fields["mass"]
                ratio = ratio.at[b].set(fields["body_mass"][b] / field("body_mass")[b])
            m0, arm0 = field("dof_M0"), field("dof_armature")
            arm = fields.get("dof_armature", arm0)
            r = ratio[m.dof_bodyid[simple]]
            fields["dof_M0"] = m0.at[simple].set((m0[simple] - arm0[simple]) * r + arm[simple])
        return fields

    # ---- sampling ---------------------------------------------------------------------------

    def _directions(self, values: dict[str, jax.Array], name: str, n: int) -> jax.Array:
        """`n` unit vectors, uniform on the sphere, drawn for factor `name` (one per camera)."""
        v = jax.random.normal(values[f"{name}/key"], (n, 3))
        return v / jnp.linalg.norm(v, axis=1, keepdims=True)

    def sample(self, key: jax.Array) -> dict[str, jax.Array]:
        """Each factor's value for the episode whose reset key is `key` (pure JAX, one env);
        a camera factor also gets the key of its directions (`NAME/key`)."""
        out = {}
        for f in self.factors:
            u = jax.random.uniform(jax.random.fold_in(key, _salt(f.name)), (), jnp.float32)
            if FACTORS[f.name].integer:
                v = jnp.minimum(f.low + jnp.floor(u * (f.high - f.low + 1)), f.high)
            else:
                v = f.low + u * (f.high - f.low)
            out[f.name] = jnp.asarray(f.low if f.fixed else v, jnp.float32)
            if f.name in CAMERA_FACTORS:
                out[f"{f.name}/key"] = jax.random.fold_in(key, _salt(f"{f.name}/direction"))
        return out

    def _noisy_obs(self, obs: jax.Array, values: dict[str, jax.Array], key: jax.Array) -> jax.Array:
        """The observation the policy reads: `obs` with this step's sensing noise."""
        keys = jax.random.split(key, 4)
        for name, idx, k in (
            ("joint_noise", self._joint_idx, keys[0]),
            ("object_noise", self._object_idx, keys[1]),
        ):
            if name in values and idx.size:
                obs = obs.at[idx].add(values[name] * jax.random.normal(k, idx.shape))
        idx = self._range_idx
        if idx.size and ("depth_noise" in values or "depth_dropout" in values):
            top = jnp.asarray(self._range_max)
            r = obs[idx]
            hit = r < top
            if "depth_noise" in values:
                noisy = r + values["depth_noise"] * jax.random.normal(keys[2], idx.shape)
                r = jnp.where(hit, jnp.clip(noisy, 0.0, top), r)
            if "depth_dropout" in values:
                lost = jax.random.uniform(keys[3], idx.shape) < values["depth_dropout"]
                r = jnp.where(lost, top, r)
            obs = obs.at[idx].set(r)
        return obs

    # ---- the scene contract ---------------------------------------------------------------

    def _inner_view(self, state: State) -> State:
        """`state` as the wrapped scene knows it: the true observation, its own `info`."""
        info = dict(state.info)
        extra = info.pop(INFO_KEY)
        return state.replace(obs=extra["obs"], info=info)

    def _wrap(self, state: State, extra: dict[str, Any]) -> State:
        values = extra["values"]
        key = jax.random.fold_in(extra["key"], extra["t"])
        extra = {**extra, "obs": state.obs}
        obs = self._noisy_obs(state.obs, values, jax.random.fold_in(key, 1))
        return state.replace(obs=obs, info={**state.info, INFO_KEY: extra})

    def _randomize(self, state: State, key: jax.Array) -> State:
        values = self.sample(key)
        physics = state.physics.replace(fields=self._apply_fields(state.physics.fields, values))
        if set(IMAGE_FACTORS) & set(values):
            state = self._recast(state, physics)
            physics = state.physics
        extra: dict[str, Any] = {
            "values": values,
            "t": jnp.zeros((), jnp.int32),
            "key": jax.random.fold_in(key, _salt("noise")),
        }
        if self._factor("delay"):
            assert self.targets.hold is not None
            hold = self.targets.hold(state)
            extra["queue"] = jnp.broadcast_to(hold, (MAX_DELAY + 1, *hold.shape))
        return self._wrap(state.replace(physics=physics), extra)

    def _recast(self, state: State, physics: Any) -> State:
        """The reset state seen from this env's cameras in its light: the same joint state
        initialised with its fields (the scene's reset drew its images from the model's camera
        poses and lights), the sensor slices of the observation read anew."""
        q = physics.quantities
        physics = self.inner.backend.init(q.qpos, q.qvel, physics.fields)
        obs, layout = state.obs, self.inner.obs_layout
        for name in self.inner.sensor_shapes:
            start, size = layout[name]
            reading = physics.quantities.sensors[name].reshape(-1).astype(obs.dtype)
            obs = obs.at[start : start + size].set(reading)
        return state.replace(physics=physics, obs=obs)

    def reset(self, key: jax.Array) -> State:
        return self._randomize(self.inner.reset(key), key)

    def reset_with_seed(self, seed: jax.Array, key: jax.Array) -> State:
        return self._randomize(self.inner.reset_with_seed(seed, key), key)

    def step(self, state: State, action: jax.Array) -> State:
        extra = dict(state.info[INFO_KEY])
        values = extra["values"]
        key = jax.random.fold_in(extra["key"], extra["t"])
        if "action_noise" in values:
            noise = jax.random.normal(jax.random.fold_in(key, 0), action.shape)
            action = action + values["action_noise"] * self._action_span * noise
        if "queue" in extra:
            queue = jnp.concatenate([action[None], extra["queue"][:-1]])
            extra["queue"] = queue
            action = queue[values["delay"].astype(jnp.int32)]
        new = self.inner.step(self._inner_view(state), action)
        extra["t"] = extra["t"] + 1
        return self._wrap(new, extra)

    def episode_factors(self, state: State) -> dict[str, jax.Array]:
        """The scene's own factors, then each randomised factor's value (fixed ones omitted)."""
        out = dict(self.inner.episode_factors(self._inner_view(state)))
        values = state.info[INFO_KEY]["values"]
        out.update({f.label: values[f.name] for f in self.factors if not f.fixed})
        return out

    def episode_info(self, state: State) -> dict[str, jax.Array]:
        return self.inner.episode_info(self._inner_view(state))

    def frame_record(self, state: State) -> dict[str, jax.Array]:
        return self.inner.frame_record(self._inner_view(state))

    def sensor_frames(self, state: State) -> dict[str, jax.Array]:
        return self.inner.sensor_frames(self._inner_view(state))

    def policy_images(self, state: State) -> dict[str, jax.Array]:
        return self.inner.policy_images(self._inner_view(state))

    def randomization_targets(self) -> RandomizationTargets | None:
        return self.targets

    def cache_parts(self) -> dict[str, Any]:
        return {**self.inner.cache_parts(), "randomize": [f.text() for f in self.factors]}

    def describe(self) -> dict[str, str]:
        """The factors as the CLI writes them (for the report's options)."""
        return {f.name: f.text().partition("=")[2] for f in self.factors}


def randomize(scene: Scene, factors: Sequence[FactorRange | str]) -> Scene:
    """`scene` with `factors` randomised per seed (``NAME=LOW:HIGH`` strings or ranges); the
    scene itself when there are none, so nominal runs are exactly today's."""
    ranges = parse_factors(factors)
    return Randomized(scene, ranges) if ranges else scene
