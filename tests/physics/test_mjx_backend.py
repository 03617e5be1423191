"""MJX's ``max_contact_points`` cap on the `mjx` backend: exact while it drops only inactive
contacts, and an env where it may drop an active one is reported not ok (counted diverged).

Three boxes rest on a plane, apart, and a ball falls onto one of them. MJX gives every
candidate pair its contact slots (box-plane, box-box, ball-plane, ball-box: one condim group);
about a dozen are active at a time. References: the same scene uncapped on `mjx` (capping
must not change the physics) and MuJoCo C (the physics itself).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.physics import QuantitySpec, make_backend
from openral_mjx.physics.mjx_backend import capped_contact_groups

XML = """
<mujoco>
  <option timestep="0.004"/>
  <worldbody>
    <geom type="plane" size="1 1 0.1"/>
    <body name="a" pos="0 0 0.05"><freejoint/><geom type="box" size="0.05 0.05 0.05"/></body>
    <body name="b" pos="0.3 0 0.05"><freejoint/><geom type="box" size="0.05 0.05 0.05"/></body>
    <body name="c" pos="0 0.3 0.05"><freejoint/><geom type="box" size="0.05 0.05 0.05"/></body>
    <body name="ball" pos="0.31 0.01 0.3">
      <freejoint/><geom type="sphere" size="0.03" mass="0.1"/>
    </body>
  </worldbody>
</mujoco>
"""
BODIES = ("a", "b", "c", "ball")
STEPS, SUBSTEPS = 40, 2


def spec_with(cap: int | None, name: str = "max_contact_points") -> mujoco.MjSpec:
    spec = mujoco.MjSpec.from_string(XML)
    if cap is not None:
        spec.add_numeric(name=name, data=[cap])
    return spec


def simulate(cap: int | None) -> tuple[np.ndarray, np.ndarray]:
    """(body positions (steps, bodies, 3), ok per step) of one env on `mjx`."""
    backend = make_backend("mjx", spec_with(cap), QuantitySpec(bodies=BODIES), SUBSTEPS)
    m = backend.mj_model
    state = jax.jit(backend.init)(jnp.asarray(m.qpos0, jnp.float32), jnp.zeros(m.nv, jnp.float32))
    step = jax.jit(backend.step)
    ctrl = jnp.zeros(m.nu, jnp.float32)
    pos, ok = [], []
    for _ in range(STEPS):
        state = step(state, ctrl)
        pos.append(np.asarray(state.quantities.body_pos))
        ok.append(bool(state.quantities.ok))
    return np.stack(pos), np.array(ok)


def reference() -> np.ndarray:
    m = mujoco.MjModel.from_xml_string(XML)
    d = mujoco.MjData(m)
    out = []
    for _ in range(STEPS):
        mujoco.mj_step(m, d, nstep=SUBSTEPS)
        out.append(d.xpos[[m.body(b).id for b in BODIES]].copy())
    return np.stack(out)


@pytest.fixture(scope="module")
def uncapped() -> tuple[np.ndarray, np.ndarray]:
    return simulate(None)


def test_the_cap_truncates_a_group_with_more_active_contacts_than_it_keeps():
    """The scene is one where the cap matters (else the tests below could not fail): MuJoCo
    C finds more active contacts than the small cap keeps, fewer than the large one."""
    m = mujoco.MjModel.from_xml_string(XML)
    d = mujoco.MjData(m)
    mujoco.mj_step(m, d, nstep=SUBSTEPS)
    active = d.ncon
    assert 4 < active <= 16, active
    groups = capped_contact_groups(spec_with(16).compile())
    assert len(groups) == 1 and groups[0] == (0, 16), groups  # fewer slots than uncapped
    assert capped_contact_groups(spec_with(None).compile()) == []


def test_cap_that_drops_only_inactive_contacts_changes_nothing(uncapped):
    pos, ok = simulate(16)
    assert ok.all() and uncapped[1].all()
    np.testing.assert_allclose(pos, uncapped[0], atol=1e-5)  # float32, another row order
    np.testing.assert_allclose(pos, reference(), atol=2e-3)  # the physics itself
    fell = reference()[:, -1, 2]
    assert fell[0] - fell[-1] > 0.1  # the ball fell onto its box: the contacts changed


def test_cap_that_may_drop_active_contacts_reports_the_env_not_ok():
    _, ok = simulate(4)
    assert not ok[0] and not ok.any(), ok  # flagged from the first step, and it stays


def test_unchecked_pair_cap_is_refused():
    with pytest.raises(ConfigError, match="max_geom_pairs"):
        make_backend("mjx", spec_with(8, "max_geom_pairs"), QuantitySpec(), SUBSTEPS)
