"""Every physics backend against MuJoCo C's own `mj_step` loop, on the composed scene.

Reference: float64 `mj_step`, ctrl held for each control step's 10 substeps, from the scene's
reset states (cube resting on the table: 4 box-box contacts from the start) under a fixed
sinusoidal action sequence that swings the arm through its range.
"""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from xla_level import for_backend

SEEDS = (0, 1, 2)
N_CONTROL = 20  # x 10 substeps = 200 physics steps


def _actions(scene) -> np.ndarray:
    lo, hi = (np.asarray(x) for x in scene.action_bounds())
    t = np.arange(N_CONTROL)[:, None]
    phase = np.arange(scene.action_size)[None, :]
    return np.clip(0.6 * np.sin(2 * np.pi * t / N_CONTROL + phase), lo, hi).astype(np.float32)


def _reference(scene, qpos0: np.ndarray, actions: np.ndarray) -> np.ndarray:
    m = scene.mj_model
    d = mujoco.MjData(m)
    d.qpos[:] = qpos0
    mujoco.mj_forward(m, d)
    out = []
    for a in actions:
        d.ctrl[:] = a
        for _ in range(scene.options.n_substeps):
            mujoco.mj_step(m, d)
        out.append(np.concatenate([d.qpos, d.qvel]))
    return np.stack(out)


def _backend_rollout(scene, qpos0: np.ndarray, actions: np.ndarray) -> np.ndarray:
    backend = scene.backend

    def run(q0):
        state = backend.init(q0, jnp.zeros(scene.mj_model.nv, jnp.float32))

        def body(s, a):
            s = backend.step(s, a)
            return s, jnp.concatenate([s.quantities.qpos, s.quantities.qvel])

        return jax.lax.scan(body, state, jnp.asarray(actions))[1]

    options = for_backend(backend.name)  # MJX's physics compiled optimised (xla_level)
    return np.asarray(jax.jit(jax.vmap(run), compiler_options=options)(jnp.asarray(qpos0)))


@pytest.fixture(scope="module")
def initial_qpos(push_c) -> np.ndarray:
    keys = jnp.stack([jax.random.split(jax.random.PRNGKey(s))[0] for s in SEEDS])
    return np.asarray(jax.vmap(push_c.reset)(keys).physics.quantities.qpos)


@pytest.fixture(scope="module")
def reference(push_c, initial_qpos) -> np.ndarray:
    actions = _actions(push_c)
    return np.stack([_reference(push_c, q.astype(np.float64), actions) for q in initial_qpos])


def test_c_backend_matches_mj_step(push_c, initial_qpos, reference):
    got = _backend_rollout(push_c, initial_qpos, _actions(push_c))
    # Same engine, same float64 state carried bit-exactly between control steps; only the
    # float32 readout rounds (measured worst case 2.3e-7).
    np.testing.assert_allclose(got, reference, rtol=0, atol=1e-6)


@pytest.mark.parametrize(
    "fixture", [pytest.param(f, marks=pytest.mark.heavy) for f in ("push_mjx", "push_warp")]
)
def test_float32_backends_match_mj_step(fixture, request, initial_qpos, reference):
    """MJX's JAX and MuJoCo-Warp (CPU mode here) implementations run in float32 with the same
    solver settings (6 Newton iterations). Measured worst cases over 200 steps: arm joints
    2.6e-7 (JAX) / 2.9e-7 (Warp) rad, resting-cube position 1.4e-4 m (contact solver in
    float32), arm joint speeds 6.8e-6 / 2.2e-6 rad/s at speeds up to 5 rad/s. The bounds allow
    ~4x that."""
    scene = request.getfixturevalue(fixture)
    got = _backend_rollout(scene, initial_qpos, _actions(scene))
    nq, robot, a = scene.mj_model.nq, scene.robot_qpos_adr, scene.cube_qpos_adr
    np.testing.assert_allclose(got[..., robot], reference[..., robot], atol=1e-6)
    np.testing.assert_allclose(got[..., a : a + 3], reference[..., a : a + 3], atol=5e-4)
    np.testing.assert_allclose(got[..., nq + robot], reference[..., nq + robot], atol=3e-5)
