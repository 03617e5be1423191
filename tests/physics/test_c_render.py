"""RGB cameras on the `c` backend: MuJoCo's own renderer, per env, from the state a step ends in."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from openral_mjx.physics import QuantitySpec
from openral_mjx.physics.c_backend import CBackend
from openral_mjx.physics.cameras import RgbSpec
from openral_mjx.physics.gl import FrameRenderer

XML = """
<mujoco>
  <worldbody>
    <light pos="0 0 3"/>
    <camera name="top" pos="0 0 2"/>
    <geom type="plane" size="2 2 0.1" rgba="0.2 0.3 0.4 1"/>
    <body name="ball" pos="0 0 0.5">
      <freejoint/>
      <geom size="0.2" rgba="0.9 0.2 0.1 1"/>
    </body>
  </worldbody>
</mujoco>
"""


def test_c_draws_the_state_each_env_ends_in(gl: str) -> None:
    spec = mujoco.MjSpec.from_string(XML)
    backend = CBackend(spec, QuantitySpec(sensors=(RgbSpec("top", 24, 16),)), 5)
    try:
        qpos = np.zeros((2, 7), np.float32)
        qpos[:, 2], qpos[:, 3] = 0.5, 1.0
        qpos[1, 0] = 0.4  # the second env's ball off centre
        init = jax.jit(jax.vmap(backend.init))
        state = init(jnp.asarray(qpos), jnp.zeros((2, 6), jnp.float32))
        ctrl = jnp.zeros((2, 0), jnp.float32)
        after = jax.jit(jax.vmap(backend.step))(state, ctrl)
        kept = jax.jit(jax.vmap(lambda s, c: backend.step(s, c, render=False)))(state, ctrl)

        m = backend.host_model
        d = mujoco.MjData(m)
        with FrameRenderer(mujoco.MjModel.from_xml_string(XML), 24, 16, gl) as r:
            for i in range(2):  # MuJoCo's renderer on the state each step ended in
                d.qpos[:], d.qvel[:] = after.quantities.qpos[i], after.quantities.qvel[i]
                mujoco.mj_forward(m, d)
                want = r.render(d, m.camera("top").id)
                got = np.round(np.asarray(after.quantities.sensors["rgb_top"][i]) * 255)
                assert np.abs(got - want).max() <= 1  # float32 qpos in the check, not the step
        first = np.asarray(state.quantities.sensors["rgb_top"])
        assert not np.array_equal(first[0], first[1])  # each env its own image
        np.testing.assert_array_equal(np.asarray(kept.quantities.sensors["rgb_top"]), first)
    finally:
        backend.close()


def test_unknown_camera_is_a_one_line_error(gl: str) -> None:
    from openral_mjx.core.errors import ConfigError

    spec = mujoco.MjSpec.from_string(XML)
    with pytest.raises(ConfigError, match="unknown camera 'side'; valid: top"):
        CBackend(spec, QuantitySpec(sensors=(RgbSpec("side", 8, 8),)), 1)
