"""Per-env model fields and mocap targets on the backends, against MuJoCo C run by hand.

A post (a fixed body) stands at a different x in each env (`PhysicsState.fields["body_pos"]`);
a mocap target drags a welded ball towards it, so each env's ball meets its own post at its own
time. The reference steps MuJoCo C directly on a model copy with that env's post position.
"""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.physics import PhysicsSettings, QuantitySpec, c_backend, make_backend

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


def reference(model: mujoco.MjModel, after_step: bool = False) -> np.ndarray:
    """Ball positions (envs, steps, 3) stepped by MuJoCo C on per-env model copies: as
    `mj_step` leaves them, or with `after_step` those of the state it ends in."""
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
            if after_step:
                mujoco.mj_kinematics(m, d)
            out[i, t] = d.xpos[m.body("ball").id]
    return out


def simulate(
    backend_name: str, after_step: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ball positions (envs, steps, 3), post positions read back, fields read back)."""
    spec = mujoco.MjSpec.from_string(XML)
    backend = make_backend(
        backend_name,
        spec,
        QuantitySpec(bodies=("ball", "post"), geoms=("ball",), poses_after_step=after_step),
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


# mjx: its per-env fields and mocap are checked by the poses-after-step test below, whose one
# MJX compile (~30 s on 2 cores) covers both
@pytest.mark.parametrize("backend", ["c", pytest.param("warp", marks=pytest.mark.slow)])
def test_per_env_body_pos_and_mocap(backend, expected, monkeypatch):
    if backend == "warp":
        pytest.importorskip("warp")
    # c: no memory budget for model copies, so one thread steps the five envs in two slices
    monkeypatch.setattr(c_backend, "COPY_BUDGET", 0)
    balls, posts, fields = simulate(backend)
    np.testing.assert_allclose(posts[:, 0], POSTS, atol=1e-6)  # each env's own post
    np.testing.assert_array_equal(fields[:, 0], POSTS.astype(np.float32))  # carried along
    tol = 1e-5 if backend == "c" else 5e-3  # c: the same engine; mjx/warp: float32, own solver
    np.testing.assert_allclose(balls, expected, atol=tol)


@pytest.mark.parametrize("backend", ["c", "mjx"])
def test_poses_after_step_are_those_of_the_state_the_step_ends_in(backend, monkeypatch):
    """`poses_after_step`: the poses MuJoCo's kinematics gives the stepped state, one physics
    step later than `mj_step` leaves them; the simulation itself does not change. Each env's
    post stands where its field puts it (the per-env fields on mjx)."""
    monkeypatch.setattr(c_backend, "COPY_BUDGET", 0)  # c: per-env models, in two slices
    m = mujoco.MjModel.from_xml_string(XML)
    balls, posts, fields = simulate(backend, after_step=True)
    np.testing.assert_allclose(posts[:, 0], POSTS, atol=1e-6)  # each env's own post
    np.testing.assert_array_equal(fields[:, 0], POSTS.astype(np.float32))  # carried along
    tol = 1e-5  # measured: c 0 (the same engine), mjx 6e-8
    np.testing.assert_allclose(balls, reference(m, after_step=True), atol=tol)
    stale = np.abs(reference(m) - reference(m, after_step=True)).max()
    assert stale > 100 * tol, stale  # 3 mm: the readouts differ (else the test could not fail)


def test_c_model_copies_forget_fields_no_longer_given():
    """A per-env copy written with one set of fields, then stepped with another, holds the
    model's own values of the fields it is no longer given, and rewrites only changed rows."""
    b = make_backend("c", mujoco.MjSpec.from_string(XML), QuantitySpec(), SUBSTEPS)
    m = b.host_model
    moved = np.repeat(m.body_pos[None], 2, 0) + 0.5
    b._models(2, ("body_pos",), (moved,))
    models = b._models(2, ("dof_damping",), (np.full((2, m.nv), 3.0),))
    for c in models:
        np.testing.assert_array_equal(c.body_pos, m.body_pos)
        np.testing.assert_array_equal(c.dof_damping, 3.0)
    models[1].dof_damping[:] = 7.0  # unchanged values are not written again...
    models = b._models(2, ("dof_damping",), (np.full((2, m.nv), 3.0),))
    assert models[1].dof_damping[0] == 7.0
    models = b._models(2, ("dof_damping",), (np.full((2, m.nv), 4.0),))  # ...changed ones are
    assert models[1].dof_damping[0] == 4.0


def test_c_model_copies_keep_float64_values_that_came_back_rounded():
    """Fields cross JAX as float32: an env's value that is the model's own value rounded
    keeps the float64 original (MetaWorld's plate-slide ran 37 steps slower on a channel
    position rounded by 3e-10 m); a value that differs is written as given."""
    spec = mujoco.MjSpec.from_string(XML.replace('pos="0 0.5 0.05"', 'pos="0 0.6 0.015"'))
    b = make_backend("c", spec, QuantitySpec(), SUBSTEPS)
    m = b.host_model
    slider = m.body("slider").id
    rounded = np.repeat(m.body_pos[None].astype(np.float32), 2, 0)
    assert rounded[0, slider, 1] != m.body_pos[slider, 1]  # 0.6 is not a float32
    rounded[1, slider, 0] = np.float32(0.25)
    models = b._models(2, ("body_pos",), (rounded.astype(np.float64),))
    np.testing.assert_array_equal(models[0].body_pos, m.body_pos)
    assert models[1].body_pos[slider, 0] == np.float32(0.25)
    assert models[1].body_pos[slider, 1] == m.body_pos[slider, 1]


def test_c_init_with_fields_unbatched_equals_a_batch_of_one():
    """`init` called outside `vmap` (a scene's reset of one env) takes fields without a lead
    axis: the post moved by its field shows in the pose readout, as in a batch of one."""
    b = make_backend("c", mujoco.MjSpec.from_string(XML), QuantitySpec(bodies=("post",)), 1)
    m = b.mj_model
    moved = jnp.asarray(m.body_pos, jnp.float32).at[m.body("post").id, 0].set(0.5)
    qpos, qvel = jnp.asarray(m.qpos0, jnp.float32), jnp.zeros(m.nv, jnp.float32)
    one = jax.jit(b.init)(qpos, qvel, {"body_pos": moved})
    batch = jax.jit(jax.vmap(b.init))(qpos[None], qvel[None], {"body_pos": moved[None]})
    np.testing.assert_allclose(np.asarray(one.quantities.body_pos)[0, 0], 0.5, atol=1e-6)
    np.testing.assert_array_equal(one.quantities.body_pos, batch.quantities.body_pos[0])


def test_unknown_field_is_a_config_error():
    spec = mujoco.MjSpec.from_string(XML)
    backend = make_backend("c", spec, QuantitySpec(bodies=("ball",)), SUBSTEPS)
    m = backend.mj_model
    with pytest.raises(ConfigError, match=r"cannot vary per env.*body_pos"):
        backend.init(jnp.asarray(m.qpos0), jnp.zeros(m.nv), fields={"opt_timestep": jnp.ones(())})


# ---- the physics fields `--randomize` varies ---------------------------------------------------

PHYSICS_XML = """
<mujoco>
  <option timestep="0.004"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1" friction="0.05 0.005 0.0001"/>
    <body name="puck" pos="0 0 0.021">
      <freejoint/><geom name="puck" type="box" size="0.02 0.02 0.02" mass="0.1"/>
    </body>
    <body name="slider" pos="0 0.5 0.05">
      <joint name="slide" type="slide" axis="1 0 0" damping="0.5" armature="0.01"/>
      <geom type="box" size="0.02 0.02 0.02" mass="0.3" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator><position joint="slide" kp="20"/></actuator>
</mujoco>
"""
# Per env: puck friction, slider mass, servo kp, joint damping, joint armature.
PHYSICS = np.array(
    [
        [0.1, 0.3, 20.0, 0.5, 0.01],
        [0.3, 0.6, 10.0, 1.5, 0.05],
        [0.6, 0.2, 40.0, 0.1, 0.002],
        [0.9, 1.0, 5.0, 3.0, 0.1],
    ]
)


def physics_fields(m: mujoco.MjModel) -> dict[str, np.ndarray]:
    """The model fields of each env (float32, as a JAX state carries them)."""
    n = len(PHYSICS)
    out = {
        k: np.repeat(getattr(m, k)[None], n, 0).astype(np.float32)
        for k in (
            "geom_friction",
            "body_mass",
            "body_inertia",
            "actuator_gainprm",
            "actuator_biasprm",
            "dof_damping",
            "dof_armature",
        )
    }
    puck, slider, dof = m.geom("puck").id, m.body("slider").id, m.joint("slide").dofadr[0]
    for i, (friction, mass, kp, damping, armature) in enumerate(PHYSICS):
        out["geom_friction"][i, puck, 0] = friction
        out["body_inertia"][i, slider] *= mass / m.body_mass[slider]
        out["body_mass"][i, slider] = mass
        out["actuator_gainprm"][i, 0, 0] = kp
        out["actuator_biasprm"][i, 0, 1] = -kp
        out["dof_damping"][i, dof] = damping
        out["dof_armature"][i, dof] = armature
    # MuJoCo C reads a simple body's inertia from `dof_M0`, which `mj_setConst` derives.
    out["dof_M0"] = np.repeat(m.dof_M0[None], n, 0).astype(np.float32)
    for i in range(n):
        mi = copy.copy(m)
        for k in ("body_mass", "body_inertia", "dof_armature"):
            getattr(mi, k)[:] = out[k][i]
        mujoco.mj_setConst(mi, mujoco.MjData(mi))
        out["dof_M0"][i] = mi.dof_M0
    return out


def physics_reference() -> np.ndarray:
    """(puck x, slider q) per env and step, from MuJoCo C on model copies with the env's
    fields (the same float32 values)."""
    m = mujoco.MjModel.from_xml_string(PHYSICS_XML)
    fields = physics_fields(m)
    out = np.zeros((len(PHYSICS), STEPS, 2))
    for i in range(len(PHYSICS)):
        mi = mujoco.MjModel.from_xml_string(PHYSICS_XML)
        for k, v in fields.items():
            getattr(mi, k)[:] = v[i]
        d = mujoco.MjData(mi)
        d.qvel[0] = 1.0  # the puck slides off at 1 m/s
        mujoco.mj_forward(mi, d)
        for t in range(STEPS):
            d.ctrl[:] = 0.2
            mujoco.mj_step(mi, d, nstep=SUBSTEPS)
            out[i, t] = d.qpos[0], d.qpos[7]
    return out


@pytest.mark.parametrize(
    "backend",
    [
        "c",
        # ~35 s of MJX compile on 2 cores; run with -m slow (benchmarks/gpu_runs.sh rand-test)
        pytest.param("mjx", marks=pytest.mark.slow),
        pytest.param("warp", marks=pytest.mark.slow),
    ],
)
def test_per_env_physics_fields(backend):
    """Friction, mass (with inertia), servo gain, damping and armature, each env its own:
    trajectories match MuJoCo C on per-env model copies, and they differ between envs.
    `dof_M0` comes along as `mj_setConst` derives it (MuJoCo C's inertia of simple bodies;
    MJX computes it from the mass)."""
    if backend == "warp":
        pytest.importorskip("warp")
    expected = physics_reference()
    assert np.ptp(expected[:, -1, 0]) > 0.05 and np.ptp(expected[:, -1, 1]) > 0.02
    b = make_backend(
        backend,
        mujoco.MjSpec.from_string(PHYSICS_XML),
        QuantitySpec(),
        SUBSTEPS,
        PhysicsSettings(threads=1),
    )
    m = b.mj_model
    fields = {k: jnp.asarray(v) for k, v in physics_fields(m).items()}
    n = len(PHYSICS)
    qpos = jnp.tile(jnp.asarray(m.qpos0, jnp.float32), (n, 1))
    qvel = jnp.zeros((n, m.nv), jnp.float32).at[:, 0].set(1.0)
    state = jax.jit(jax.vmap(b.init))(qpos, qvel, fields)
    step = jax.jit(jax.vmap(b.step))
    out = []
    for _ in range(STEPS):
        state = step(state, jnp.full((n, 1), 0.2))
        q = np.asarray(state.quantities.qpos)
        out.append(np.stack([q[:, 0], q[:, 7]], 1))
    tol = 1e-5 if backend == "c" else 2e-3  # c: the same engine; mjx/warp: float32, own solver
    np.testing.assert_allclose(np.stack(out, 1), expected, atol=tol)
