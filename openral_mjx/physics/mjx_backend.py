"""MJX (JAX implementation): physics as pure JAX, on any JAX device.

MJX's JAX collision has no broadphase: every candidate contact of the model is a slot, and a
constraint row, every step, active or not. A scene may cap the slots with MJX's
``max_contact_points`` numeric (MJX keeps the deepest per condim); dropping a contact that
would have been active changes the physics silently, so an env where a capped group's every
kept contact is active (one more may have been dropped) reports ``ok = False``, and the runner
counts it diverged. MJX's other cap, ``max_geom_pairs``, culls by bounding spheres before
collision and cannot be checked this way, so it is refused.
"""

from __future__ import annotations

import contextlib
import io

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

# mujoco.mjx prints "Failed to import warp" to stdout when warp-lang is absent (an optional
# extra); keep that out of our CLI's output.
with contextlib.redirect_stdout(io.StringIO()):
    from mujoco import mjx

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.rotations import mat_to_quat
from openral_mjx.physics.base import (
    PhysicsBackend,
    PhysicsState,
    Quantities,
    all_finite,
    check_fields,
    reference_qpos,
)
from openral_mjx.physics.contact_sensors import add_contact_sensors, sensordata_addresses
from openral_mjx.physics.visual_meshes import collision_meshes_only

_CAP = "max_contact_points"
# One physics step as a `jit` of its own: JAX then traces MJX's step once per model and data
# layout and reuses it, where the observation probe, Warp's warm-up and the episode's scan
# (traced again to settle its carry's batching) each traced it anew.
_physics_step = jax.jit(mjx.step)


def without_texels(mx: mjx.Model) -> mjx.Model:
    """`mx` with its textures' texels and the meshes' texture coordinates emptied: neither
    MJX's step nor MuJoCo-Warp's render reads them from the model (its render context holds
    its own copies, built from the `MjModel`). MJX keeps the model's NumPy fields as static
    pytree metadata and checksums every one of them each time the model is flattened (every
    trace of a step, a render, a `vmap`): 147 MB of texels on a LIBERO task with cameras,
    ~7 s of its start-up on the 2-core machine spent in `zlib.crc32`."""
    return mx.replace(
        tex_data=np.zeros(0, mx.tex_data.dtype),
        mesh_texcoord=np.zeros((0, 2), mx.mesh_texcoord.dtype),
    )


def numeric(m: mujoco.MjModel, name: str) -> int | None:
    """The model's integer custom numeric `name` (MJX's contact caps), or None."""
    i = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_NUMERIC, name)
    return None if i < 0 else int(m.numeric_data[m.numeric_adr[i]])


def capped_contact_groups(m: mujoco.MjModel) -> list[tuple[int, int]]:
    """(first slot, slots) of each condim group of MJX's contact slots that the model's
    ``max_contact_points`` truncates, in the order MJX lays them out (by condim)."""
    from mujoco.mjx._src import collision_driver

    i = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_NUMERIC, _CAP)
    adr = m.numeric_adr[i] if i >= 0 else -1
    cap = int(m.numeric_data[adr]) if i >= 0 else -1
    if cap < 0:
        return []
    m.numeric_data[adr] = -1  # the uncapped layout, read through MJX's own function
    try:
        full = collision_driver.make_condim(m)
    finally:
        m.numeric_data[adr] = cap
    groups, start = [], 0
    for dim in np.unique(full):
        n = int((full == dim).sum())
        if n > cap:
            groups.append((start, cap))
        start += min(n, cap)
    return groups


class MjxBackend(PhysicsBackend):
    """`mjx.step` under `lax.fori_loop`; the state's `data` is an `mjx.Data`.

    Subclasses change the MJX implementation (`impl`) by overriding `_put`, `_put_model`,
    `_make_data` and `_data_ok`; the stepping and the readout are shared.
    """

    name = "mjx"
    impl = "jax"
    exportable = True

    def _setup(self, spec: mujoco.MjSpec) -> None:
        self._contact_adr: list[np.ndarray] = []
        if self.quantity_spec.contacts:
            if self.quantity_spec.poses_after_step:
                raise ConfigError(
                    "contact quantities read the step's own collision: no poses_after_step"
                )
            with_sensors = spec.copy()
            ranges = add_contact_sensors(
                with_sensors, self.mj_model, self.quantity_spec.contacts, subtrees=False
            )
            self.mj_model = with_sensors.compile()  # ids unchanged: sensors come last
            self._contact_adr = sensordata_addresses(self.mj_model, ranges)
            spec = with_sensors
        # The model MJX steps: `mj_model` less the meshes only cameras see (`visual_meshes`).
        self.physics_model = collision_meshes_only(spec, self.mj_model)
        m = self.mj_model
        pairs_cap = numeric(m, "max_geom_pairs")
        if self.impl == "jax" and pairs_cap is not None and pairs_cap >= 0:
            raise ConfigError(
                "the scene sets MJX's max_geom_pairs, which drops contacts unchecked; the "
                f"mjx backend accepts {_CAP} instead (an env that may lose an active contact "
                "to it is counted diverged)"
            )
        # Capped contact groups, and the largest distance at which a contact can be active
        # (MJX: dist < margin - gap); a capped group is safe while its last kept contact
        # (the least deep) lies beyond that.
        self._capped = capped_contact_groups(m) if self.impl == "jax" else []
        colliding = (m.geom_contype | m.geom_conaffinity) > 0
        margins = np.concatenate([m.geom_margin[colliding], m.pair_margin, [0.0]])
        self._active_below = float(margins.max())
        self.mx = self._put_model()
        self._body_ids = jnp.asarray(self.body_ids, dtype=jnp.int32)
        self._site_ids = jnp.asarray(self.site_ids, dtype=jnp.int32)
        self._geom_ids = jnp.asarray(self.geom_ids, dtype=jnp.int32)
        self._park_qpos = jnp.asarray(reference_qpos(self.mj_model), dtype=jnp.float32)

    def _put(self, m: mujoco.MjModel) -> mjx.Model:
        """`m` put on this backend's device with its implementation, without texels."""
        return without_texels(mjx.put_model(m, impl=self.impl, device=self.home_device()))

    def _put_model(self) -> mjx.Model:
        return self._put(self.physics_model)

    def _make_data(self) -> mjx.Data:
        return mjx.make_data(self.mx, device=self.home_device())

    def _data_ok(self, d: mjx.Data) -> jax.Array:
        """False where this env's physics can no longer be trusted."""
        return all_finite(d.qpos, d.qvel)

    def _contacts_kept(self, d: mjx.Data) -> jax.Array:
        """False where a capped contact group kept only active contacts in `d`'s last
        collision (an active one may have been dropped)."""
        ok = jnp.ones((), bool)
        for start, n in self._capped:
            kept = d._impl.contact.dist[start : start + n]
            ok &= jnp.max(kept) >= self._active_below
        return ok

    def _readout(
        self,
        d: mjx.Data,
        fields: dict[str, jax.Array] | None = None,
        kept: dict[str, jax.Array] | None = None,
    ) -> tuple[mjx.Data, Quantities]:
        """The quantities of `d` (and `d` itself: a backend that renders threads its
        execution token through the data); `fields`: this env's model fields. `kept`: the
        rendered sensors' readings to carry over instead of drawing them (a step that does
        not render); unused here, where nothing is rendered."""
        del kept
        q = Quantities(
            qpos=d.qpos,
            qvel=d.qvel,
            body_pos=d.xpos[self._body_ids],
            body_quat=d.xquat[self._body_ids],
            site_pos=d.site_xpos[self._site_ids],
            geom_pos=d.geom_xpos[self._geom_ids],
            geom_quat=mat_to_quat(d.geom_xmat[self._geom_ids]),
            ok=self._data_ok(d),
            sensors=self.read_sensors(d.xpos, d.xquat, fields),
            contacts=self._touching(d),
            overflowed=self._overflowed(d),
        )
        return d, q

    def _overflowed(self, d: mjx.Data) -> jax.Array:
        """Whether a buffer of `d`'s last step overflowed (MJX's own buffers never do; a
        capped contact group is `_contacts_kept`'s, checked per physics step)."""
        del d
        return jnp.zeros((), bool)

    def _touching(self, d: mjx.Data) -> jax.Array | None:
        """Whether each `QuantitySpec.contacts` pair touches, from the contact sensors the
        step's forward pass computed (before its integration, as on `c`); all False at
        `init`, which computes poses only."""
        if not self._contact_adr:
            return None
        return jnp.stack([jnp.sum(d.sensordata[a]) > 0 for a in self._contact_adr])

    def model(self, fields: dict[str, jax.Array]) -> mjx.Model:
        """The MJX model with this env's `fields` (under `vmap`, a batched model: MJX reads
        per-env values of those fields like MuJoCo Playground's domain randomisation)."""
        return self.mx.replace(**fields) if fields else self.mx

    def init(
        self, qpos: jax.Array, qvel: jax.Array, fields: dict[str, jax.Array] | None = None
    ) -> PhysicsState:
        fields = dict(fields or {})
        check_fields(fields)
        # Kinematics alone yields every quantity task logic reads (poses); the first step
        # recomputes the rest (`mj_step` begins with a full forward pass), so the trajectory is
        # the same as after `mjx.forward`, which would double the traced physics and add
        # seconds to every compile.
        d = self._make_data().replace(qpos=qpos, qvel=qvel)
        d, q = self._readout(self._kinematics(self.model(fields), d, fields), fields)
        return PhysicsState(data=d, quantities=q, fields=fields)

    def _kinematics(
        self, mx: mjx.Model, d: mjx.Data, fields: dict[str, jax.Array] | None = None
    ) -> mjx.Data:
        """Poses from joint positions (what `init` reports before the first step); `fields`:
        this env's model fields (already in `mx`, for what reads them beside it)."""
        return mjx.kinematics(mx, d)

    def step(
        self,
        state: PhysicsState,
        ctrl: jax.Array,
        mocap: tuple[jax.Array, jax.Array] | None = None,
        render: bool = True,
    ) -> PhysicsState:
        # A diverged env (already counted a failure) is parked at the model's reference pose,
        # so its garbage cannot spread, e.g. into Warp's contact buffer shared by the batch.
        d, ok = state.data, state.quantities.ok
        d = d.replace(
            qpos=jnp.where(ok, d.qpos, self._park_qpos),
            qvel=jnp.where(ok, d.qvel, 0.0),
            qacc_warmstart=jnp.where(ok, d.qacc_warmstart, 0.0),
            ctrl=ctrl,
        )
        if mocap is not None:
            d = d.replace(mocap_pos=mocap[0], mocap_quat=mocap[1])
        mx = self.model(state.fields)

        def substep(_: int, carry: tuple[mjx.Data, jax.Array]) -> tuple[mjx.Data, jax.Array]:
            d, kept = carry
            d = _physics_step(mx, d)
            return d, kept & self._contacts_kept(d)

        d, kept = jax.lax.fori_loop(0, self.n_substeps, substep, (d, jnp.ones((), bool)))
        if self.quantity_spec.poses_after_step:  # the next step's forward pass redoes them
            d = self._kinematics(mx, d, state.fields)
        # a step that does not render keeps the previous images (`PhysicsBackend.step`)
        same = None if render else {k: state.quantities.sensors[k] for k in self.rendered}
        d, q = self._readout(d, state.fields, same)
        # both sticky: a parked env is finite again, but its episode stays what it was
        overflowed = state.quantities.overflowed | q.overflowed | (ok & ~kept)
        q = q.replace(ok=q.ok & kept & ok, overflowed=overflowed)
        return PhysicsState(data=d, quantities=q, fields=state.fields)
