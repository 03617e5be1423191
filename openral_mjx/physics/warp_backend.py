"""MJX with the MuJoCo-Warp implementation: Warp kernels called from JAX (CUDA; CPU for tests).

Warp keeps contacts in one buffer shared by every env of a batch (`naconmax` = capacity per env
x envs per device) and constraints in per-env rows (`njmax`), so buffers are sized for a batch
at construction (`PhysicsSettings.batch_size`, `contacts_per_env`). An env whose contacts or
constraints overflow those buffers, or whose state goes non-finite, reports `ok = False` and
the runner counts it diverged: an overflow is never a silently wrong episode. Hitting the
solver's iteration limit is expected with the scenes' few Newton iterations (MuJoCo C does the
same), so those two warnings are masked rather than printed every step.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.rotations import quat_to_mat
from openral_mjx.physics.base import (
    WARP_GRAPHS,
    Quantities,
    all_finite,
    reference_qpos,
    warp_installed,
)
from openral_mjx.physics.cameras import SensorSpec, sensor_key
from openral_mjx.physics.mjx_backend import MjxBackend, mjx, without_texels
from openral_mjx.physics.warp_render import WarpCameras, renderable
from openral_mjx.raycast import LaserSpec

INSTALL_HINT = "pip install 'openral_mjx[warp]' (warp-lang)"


class WarpBackend(MjxBackend):
    """`mjx.step` with `impl='warp'`; same scenes and task logic as `mjx`."""

    name = "warp"
    impl = "warp"
    exportable = False  # Warp's FFI calls are not serializable; it traces in ~1 s anyway

    def _rendered(self, sensors: tuple[SensorSpec, ...]) -> frozenset[str]:
        """Cameras go through MuJoCo-Warp's batch renderer where one context can serve them
        (see `warp_render.renderable`); lasers and the other depth cameras are ray cast."""
        self._render_specs = renderable([s for s in sensors if not isinstance(s, LaserSpec)])
        return frozenset(sensor_key(s) for s in self._render_specs)

    def _setup(self, spec: mujoco.MjSpec) -> None:
        if not warp_installed():
            raise ConfigError(f"backend 'warp' needs warp-lang; install it with {INSTALL_HINT}")
        import warp

        # No banner or per-kernel build lines in our CLI's output; warnings still show.
        warp.config.quiet = True
        warp.config.log_level = max(warp.config.log_level, warp.LOG_WARNING)
        from mujoco.mjx.third_party.mujoco_warp._src.types import OverflowType

        # Overflows that make an env's physics wrong (dropped contacts or constraints).
        self._fatal = int(
            OverflowType.NEFC
            | OverflowType.NJMAX_NNZ
            | OverflowType.BROADPHASE
            | OverflowType.NARROWPHASE
            | OverflowType.CCD
            | OverflowType.NVMAX
            | OverflowType.EPA_HORIZON
        )
        self._warn = int(OverflowType.ALL & ~(OverflowType.ITERATIONS | OverflowType.LS_ITERATIONS))
        self._warm = False
        m, s = self.mj_model, self.settings
        self.naconmax = s.contacts_per_env * s.batch_size
        self.naccdmax = (s.ccd_contacts_per_env or s.contacts_per_env) * s.batch_size
        # Rows per env: a pyramidal friction cone takes 2 (condim - 1) rows per contact (<= 10
        # for condim 6), plus one row per dof for joint limits and one for friction loss.
        self.njmax = 10 * s.contacts_per_env + 2 * m.nv + m.neq * 6
        body = m.geom_bodyid
        static = (m.body_weldid[body] == 0) & (m.body_mocapid[body] < 0) & (body > 0)
        self._static_geoms = np.flatnonzero(static)
        super()._setup(spec)  # puts the model, which needs the overflow mask above
        self.cameras = None
        if self._render_specs:
            here = jax.process_index()
            gpus = [d for d in self.devices() if d.platform == "gpu" and d.process_index == here]
            names = [f"cuda:{d.local_hardware_id}" for d in gpus] or None
            drawn = self.mx
            if self.physics_model is not self.mj_model:  # cameras see the visual meshes
                drawn = self._put(self.mj_model)
            self.cameras = WarpCameras(self.mj_model, drawn, self._render_specs, names)

    def _put_model(self) -> mjx.Model:
        mx = super()._put_model()
        opt_impl = mx.opt._impl.replace(warn_overflow=self._warn)
        return mx.replace(opt=mx.opt.replace(_impl=opt_impl))

    def _put(self, m: mujoco.MjModel) -> mjx.Model:
        """`m` put on this backend's device with the settings' CUDA-graph mode."""
        mode = None
        if self.settings.warp_graphs is not None:
            import warp  # installed: checked by _setup

            mode = getattr(warp.JaxCallableGraphMode, WARP_GRAPHS[self.settings.warp_graphs])
        m_x = mjx.put_model(m, impl="warp", device=self.home_device(), graph_mode=mode)
        return without_texels(m_x)

    def _make_data(self) -> mjx.Data:
        return mjx.make_data(
            self.physics_model,
            impl="warp",
            naconmax=self.naconmax,
            naccdmax=self.naccdmax,
            njmax=self.njmax,
            device=self.home_device(),
        )

    def _kinematics(
        self, mx: mjx.Model, d: mjx.Data, fields: dict[str, jax.Array] | None = None
    ) -> mjx.Data:
        d = super()._kinematics(mx, d, fields)
        if self._static_geoms.size and mx is not self.mx:
            d = self._place_static_geoms(mx, d)
        return d if self.cameras is None else self.cameras.place(d, fields)

    def _place_static_geoms(self, mx: mjx.Model, d: mjx.Data) -> mjx.Data:
        """World poses of the geoms of bodies welded to the world, from this env's body poses.

        MuJoCo-Warp computes those once, from the shared model, and never again (its docs:
        per-world `body_pos` is unsafe for static bodies), so with per-env `fields` its
        collisions would meet every env's fixed bodies where the model has them. The poses of
        the bodies themselves are per env (kinematics reads the batched fields); the geoms'
        follow from them here, at `init`, and stay put like the bodies."""
        g = self._static_geoms
        b = jnp.asarray(self.mj_model.geom_bodyid[g])
        xmat = d.xmat[b]
        pos = d.xpos[b] + jnp.einsum("gij,gj->gi", xmat, mx.geom_pos[g])
        local = jax.vmap(quat_to_mat)(mx.geom_quat[g])
        return d.replace(
            geom_xpos=d.geom_xpos.at[g].set(pos),
            geom_xmat=d.geom_xmat.at[g].set(jnp.einsum("gij,gjk->gik", xmat, local)),
        )

    def _readout(
        self,
        d: mjx.Data,
        fields: dict[str, jax.Array] | None = None,
        kept: dict[str, jax.Array] | None = None,
    ) -> tuple[mjx.Data, Quantities]:
        d, q = super()._readout(d, fields)
        if self.cameras is None:
            return d, q
        if kept is not None:  # no render: the previous images (a scene observes another step)
            return d, q.replace(sensors={**q.sensors, **kept})
        images, d = self.cameras.render(d, fields)
        return d, q.replace(sensors={**q.sensors, **images})

    def _data_ok(self, d: mjx.Data) -> jax.Array:
        return all_finite(d.qpos, d.qvel) & ~self._overflowed(d)

    def _overflowed(self, d: mjx.Data) -> jax.Array:
        return jnp.any(jnp.bitwise_and(d._impl.overflow, self._fatal) != 0)

    def warm_up(self) -> None:
        """Warp builds (or loads from its cache) its kernels on the first call: one env, one
        step from the model's reference pose. The kernels take the batch size at run time, so
        this covers any batch."""
        if self._warm:
            return

        m = self.mj_model
        state = jax.jit(jax.vmap(self.init))(  # from a resting pose: no overflow warnings
            jnp.asarray(reference_qpos(m)[None], jnp.float32), jnp.zeros((1, m.nv), jnp.float32)
        )
        jax.block_until_ready(
            jax.jit(jax.vmap(self.step))(state, jnp.asarray(np.zeros((1, m.nu)), jnp.float32))
        )
        self._warm = True

    def _candidate_devices(self) -> list[jax.Device]:
        """CUDA GPUs where there are any, else the CPU devices (Warp's CPU mode, for tests;
        one unless XLA is told to split the host)."""
        gpus = [d for d in jax.devices() if d.platform == "gpu"]
        return gpus or list(jax.devices("cpu"))

    @property
    def max_batch(self) -> int:
        return self.settings.batch_size

    def describe(self) -> dict:
        return {
            **super().describe(),
            "naconmax": self.naconmax,
            "naccdmax": self.naccdmax,
            "njmax": self.njmax,
            "batch_size": self.settings.batch_size,
            # only where set: a graph mode changes speed and memory, not the episodes
            **({"warp_graphs": self.settings.warp_graphs} if self.settings.warp_graphs else {}),
        }
