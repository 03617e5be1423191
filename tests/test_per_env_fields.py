"""Per-env model fields and mocap targets on the backends, against MuJoCo C run by hand.

A post (a fixed body) stands at a different x in each env (`PhysicsState.fields["body_pos"]`);
a mocap target drags a welded ball towards it, so each env's ball meets its own post at its own
time. The reference steps MuJoCo C directly on a model copy with that env's post position.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.physics import PhysicsSettings, QuantitySpec, make_backend

XML = """
<mujoco>
  <option timestep="0.004"/>
  <worldbody>
    <geom type="plane" size="1 1 0.1"/>
    <body name="post" pos="0 0 0.1"><geom type="box" size="0.05 0.05 0.1"/></body>
    <body name="target" mocap="true" pos="0.3 0 0.05"/>
    <body name="ball" pos="0.3 0 0.05">
      <freejoint/><geom name="ball" type="sphere" size="0.04" mass="0.2"/>
    </body>
    <body name="slider" pos="0 0.5 0.05">
      <joint name="slide" type="slide" axis="1 0 0"/><geom type="box" size="0.02 0.02 0.02"/>
    </body>
  </worldbody>
  <equality><weld body1="target" body2="ball" solref="0.05 1"/></equality>
  <actuator><position joint="slide" kp="50"/></actuator>
</mujoco>
"""
# Post x per env: five, so that `c` with one thread steps them in two slices of per-env models.
POSTS = np.array([0.0, 0.04, 0.08, 0.12, 0.16])
STEPS, SUBSTEPS = 25, 4


def mocap_path(t: int) -> np.ndarray:
    """The mocap target at control step t: towards -x at 1.2 cm per step."""
    return np.array([0.3 - 0.012 * (t + 1), 0.0, 0.05])


def reference(model: mujoco.MjModel) -> np.ndarray:
    """Ball positions (envs, steps, 3) stepped by MuJoCo C on per-env model copies."""
    out = np.zeros((len(POSTS), STEPS, 3))
    post = model.body("post").id
    for i, x in enumerate(POSTS):
        m = mujoco.MjModel.from_xml_string(XML)
        m.body_pos[post] = (x, 0.0, 0.1)
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        for t in range(STEPS):
            d.mocap_pos[0] = mocap_path(t)
            d.ctrl[:] = 0.1
            mujoco.mj_step(m, d, nstep=SUBSTEPS)
            out[i, t] = d.xpos[m.body("ball").id]
    return out


def simulate(backend_name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ball positions (envs, steps, 3), post positions read back, fields read back)."""
    spec = mujoco.MjSpec.from_string(XML)
    backend = make_backend(
        backend_name,
        spec,
        QuantitySpec(bodies=("ball", "post"), geoms=("ball",)),
        SUBSTEPS,
        PhysicsSettings(threads=1),
    )
    m = backend.mj_model
    body_pos = np.repeat(m.body_pos[None], len(POSTS), 0).astype(np.float32)
    k = len(POSTS)
    body_pos[:, m.body("post").id] = np.stack([POSTS, np.zeros(k), np.full(k, 0.1)], 1)
    qpos = jnp.tile(jnp.asarray(m.qpos0, jnp.float32), (len(POSTS), 1))
    qvel = jnp.zeros((len(POSTS), m.nv), jnp.float32)
    init = jax.jit(jax.vmap(lambda q, v, b: backend.init(q, v, fields={"body_pos": b})))
    state = init(qpos, qvel, jnp.asarray(body_pos))
    quat = jnp.tile(jnp.array([[1.0, 0.0, 0.0, 0.0]]), (len(POSTS), 1, 1))
    step = jax.jit(jax.vmap(lambda s, c, p, q: backend.step(s, c, mocap=(p, q))))
    ctrl = jnp.full((len(POSTS), 1), 0.1)
    out = []
    for t in range(STEPS):
        pos = jnp.tile(jnp.asarray(mocap_path(t), jnp.float32)[None, None], (len(POSTS), 1, 1))
        state = step(state, ctrl, pos, quat)
        out.append(np.asarray(state.quantities.body_pos[:, 0]))
    posts = np.asarray(state.quantities.body_pos[:, 1])
    return np.stack(out, 1), posts, np.asarray(state.fields["body_pos"])[:, m.body("post").id]


@pytest.fixture(scope="module")
def expected() -> np.ndarray:
    return reference(mujoco.MjModel.from_xml_string(XML))


def test_reference_envs_differ(expected):
    """The posts stop the balls at different places (else the test could not fail)."""
    final_x = expected[:, -1, 0]
    assert np.all(np.diff(final_x) > 0.03), final_x


@pytest.mark.parametrize("backend", ["c", "mjx", pytest.param("warp", marks=pytest.mark.slow)])
def test_per_env_body_pos_and_mocap(backend, expected):
    if backend == "warp":
        pytest.importorskip("warp")
    balls, posts, fields = simulate(backend)
    np.testing.assert_allclose(posts[:, 0], POSTS, atol=1e-6)  # each env's own post
    np.testing.assert_array_equal(fields[:, 0], POSTS.astype(np.float32))  # carried along
    tol = 1e-5 if backend == "c" else 5e-3  # c: the same engine; mjx/warp: float32, own solver
    np.testing.assert_allclose(balls, expected, atol=tol)


def test_unknown_field_is_a_config_error():
    spec = mujoco.MjSpec.from_string(XML)
    backend = make_backend("c", spec, QuantitySpec(bodies=("ball",)), SUBSTEPS)
    m = backend.mj_model
    with pytest.raises(ConfigError, match=r"cannot vary per env.*body_pos"):
        backend.init(jnp.asarray(m.qpos0), jnp.zeros(m.nv), fields={"opt_timestep": jnp.ones(())})
