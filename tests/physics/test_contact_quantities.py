"""`QuantitySpec.contacts` (robosuite's `check_contact`) on every backend, against MuJoCo C.

A ball falls onto box b, which rests on a plane beside box a. Pairs read: b with the plane
(always touching), the ball with b (from when it lands), a with the ball (never), and a set of
two geoms (a's and b's) with the plane, which MuJoCo C reads through per-geom sensors (no
single body subtree holds exactly that set). MuJoCo C's own contact list, read after each
step, is the reference for the `c` backend; `mjx` and `warp` must agree with `c` at every step.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.physics import QuantitySpec, make_backend

XML = """
<mujoco>
  <option timestep="0.004"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <body name="a" pos="0 0 0.05">
      <freejoint/><geom name="ga" type="box" size="0.05 0.05 0.05"/>
    </body>
    <body name="b" pos="0.3 0 0.05">
      <freejoint/><geom name="gb" type="box" size="0.05 0.05 0.05"/>
    </body>
    <body name="ball" pos="0.31 0.01 0.3">
      <freejoint/><geom name="gball" type="sphere" size="0.03" mass="0.1"/>
    </body>
  </worldbody>
</mujoco>
"""
PAIRS = (
    (("gb",), ("floor",)),
    (("gball",), ("gb",)),
    (("ga",), ("gball",)),
    (("ga", "gb"), ("floor",)),
)
STEPS, SUBSTEPS = 30, 2


def touching(pairs: set[tuple[int, int]], a: set[int], b: set[int]) -> bool:
    return any((g1 in a and g2 in b) or (g1 in b and g2 in a) for g1, g2 in pairs)


def reference() -> np.ndarray:
    """Each pair's touching, after each control step, from MuJoCo C's contact list (as
    robosuite's `check_contact` reads it)."""
    m = mujoco.MjModel.from_xml_string(XML)
    d = mujoco.MjData(m)
    sets = [({m.geom(g).id for g in a}, {m.geom(g).id for g in b}) for a, b in PAIRS]
    out = []
    for _ in range(STEPS):
        mujoco.mj_step(m, d, nstep=SUBSTEPS)
        pairs = {(int(c.geom1), int(c.geom2)) for c in d.contact[: d.ncon]}
        out.append([touching(pairs, a, b) for a, b in sets])
    return np.array(out)


def rollout(backend: str) -> np.ndarray:
    spec = mujoco.MjSpec.from_string(XML)
    physics = make_backend(backend, spec, QuantitySpec(bodies=("ball",), contacts=PAIRS), SUBSTEPS)
    m = physics.mj_model
    qpos = jnp.asarray(m.qpos0, jnp.float32)[None]
    state = jax.jit(jax.vmap(physics.init))(qpos, jnp.zeros((1, m.nv), jnp.float32))
    step = jax.jit(jax.vmap(physics.step))
    out = []
    for _ in range(STEPS):
        state = step(state, jnp.zeros((1, 0), jnp.float32))
        out.append(np.asarray(state.quantities.contacts[0]))
    return np.array(out)


@pytest.fixture(scope="module")
def expected() -> np.ndarray:
    ref = reference()
    assert ref[:, 0].all() and not ref[:, 2].any()  # the scene does what the docstring says
    assert not ref[0, 1] and ref[-1, 1]  # the ball lands during the rollout
    return ref


def test_c_reads_mujocos_contact_list(expected):
    np.testing.assert_array_equal(rollout("c"), expected)


def test_mjx_reads_the_same_contacts_as_c(expected):
    np.testing.assert_array_equal(rollout("mjx"), expected)


@pytest.mark.heavy
def test_warp_reads_the_same_contacts_as_c(expected):
    pytest.importorskip("warp")
    np.testing.assert_array_equal(rollout("warp"), expected)


def test_contacts_refuse_poses_after_step():
    spec = mujoco.MjSpec.from_string(XML)
    for backend in ("c", "mjx"):
        with pytest.raises(ConfigError, match="poses_after_step"):
            make_backend(
                backend, spec, QuantitySpec(contacts=PAIRS, poses_after_step=True), SUBSTEPS
            )
