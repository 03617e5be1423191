"""MJX (JAX implementation): physics as pure JAX, on any JAX device."""

from __future__ import annotations

import contextlib
import io

import jax
import jax.numpy as jnp
import mujoco

# mujoco.mjx prints "Failed to import warp" to stdout when warp-lang is absent (an optional
# extra); keep that out of our CLI's output.
with contextlib.redirect_stdout(io.StringIO()):
    from mujoco import mjx

from openral_mjx.physics.base import (
    PhysicsBackend,
    PhysicsState,
    Quantities,
    all_finite,
    check_fields,
    mat_to_quat,
)


class MjxBackend(PhysicsBackend):
    """`mjx.step` under `lax.fori_loop`; the state's `data` is an `mjx.Data`.

    Subclasses change the MJX implementation (`impl`) by overriding `_put_model`,
    `_make_data` and `_data_ok`; the stepping and the readout are shared.
    """

    name = "mjx"
    impl = "jax"
    exportable = True

    def _setup(self, spec: mujoco.MjSpec) -> None:
        self.mx = self._put_model()
        self._body_ids = jnp.asarray(self.body_ids, dtype=jnp.int32)
        self._site_ids = jnp.asarray(self.site_ids, dtype=jnp.int32)
        self._geom_ids = jnp.asarray(self.geom_ids, dtype=jnp.int32)
        self._qpos0 = jnp.asarray(self.mj_model.qpos0, dtype=jnp.float32)

    def _put_model(self) -> mjx.Model:
        return mjx.put_model(self.mj_model, impl=self.impl, device=self.home_device())

    def _make_data(self) -> mjx.Data:
        return mjx.make_data(self.mx, device=self.home_device())

    def _data_ok(self, d: mjx.Data) -> jax.Array:
        """False where this env's physics can no longer be trusted."""
        return all_finite(d.qpos, d.qvel)

    def _readout(
        self, d: mjx.Data, fields: dict[str, jax.Array] | None = None
    ) -> tuple[mjx.Data, Quantities]:
        """The quantities of `d` (and `d` itself: a backend that renders threads its
        execution token through the data); `fields`: this env's model fields."""
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
        )
        return d, q

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
    ) -> PhysicsState:
        # A diverged env (already counted a failure) is parked at the reference pose, so its
        # garbage cannot spread, e.g. into Warp's contact buffer shared by the batch.
        d, ok = state.data, state.quantities.ok
        d = d.replace(
            qpos=jnp.where(ok, d.qpos, self._qpos0),
            qvel=jnp.where(ok, d.qvel, 0.0),
            qacc_warmstart=jnp.where(ok, d.qacc_warmstart, 0.0),
            ctrl=ctrl,
        )
        if mocap is not None:
            d = d.replace(mocap_pos=mocap[0], mocap_quat=mocap[1])
        mx = self.model(state.fields)
        d = jax.lax.fori_loop(0, self.n_substeps, lambda _, x: mjx.step(mx, x), d)
        if self.quantity_spec.poses_after_step:  # the next step's forward pass redoes them
            d = self._kinematics(mx, d, state.fields)
        d, q = self._readout(d, state.fields)
        return PhysicsState(
            data=d, quantities=q.replace(ok=q.ok & state.quantities.ok), fields=state.fields
        )
