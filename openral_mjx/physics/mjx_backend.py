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
    QuantitySpec,
    all_finite,
)


class MjxBackend(PhysicsBackend):
    """`mjx.step` under `lax.fori_loop`; the state's `data` is an `mjx.Data`."""

    name = "mjx"
    impl = "jax"

    def __init__(self, spec: mujoco.MjSpec, quantities: QuantitySpec, n_substeps: int) -> None:
        super().__init__(spec, quantities, n_substeps)
        self.mx = mjx.put_model(self.mj_model, impl=self.impl)
        self._body_ids = jnp.asarray(self.body_ids, dtype=jnp.int32)
        self._site_ids = jnp.asarray(self.site_ids, dtype=jnp.int32)

    def _quantities(self, d: mjx.Data) -> Quantities:
        qpos, qvel = d.qpos, d.qvel
        return Quantities(
            qpos=qpos,
            qvel=qvel,
            body_pos=d.xpos[self._body_ids],
            body_quat=d.xquat[self._body_ids],
            site_pos=d.site_xpos[self._site_ids],
            ok=all_finite(qpos, qvel),
        )

    def init(self, qpos: jax.Array, qvel: jax.Array) -> PhysicsState:
        d = mjx.make_data(self.mx).replace(qpos=qpos, qvel=qvel)
        d = mjx.forward(self.mx, d)
        return PhysicsState(data=d, quantities=self._quantities(d))

    def step(self, state: PhysicsState, ctrl: jax.Array) -> PhysicsState:
        d = state.data.replace(ctrl=ctrl)
        d = jax.lax.fori_loop(0, self.n_substeps, lambda _, x: mjx.step(self.mx, x), d)
        q = self._quantities(d)
        return PhysicsState(data=d, quantities=q.replace(ok=q.ok & state.quantities.ok))
