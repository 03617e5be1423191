"""Contact fidelity of so101_box: the tube fits the hole with the stated clearance, on MuJoCo C
and on MJX, with the scene's own geoms and contact parameters.

Rig: the composed scene without the robot, the block welded to the floor, the tube on a
vertical slide joint (so its axis stays vertical and its offset from the hole's axis fixed),
released at rest just above the rim and left to fall under gravity for 0.8 s. The spec's
radial clearance is (23 - 21.9) / 2 = 0.55 mm: at 0.4 mm the tube must drop through to the
floor; at 0.7 mm (0.15 mm over the clearance, off the slot's direction) and at 1 mm it must
stay on the rim, short of the insertion depth. So the effective clearance lies in
(0.4, 0.7) mm, within 0.2 mm of the spec, on both engines.
"""

import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from openral_mjx.physics.mjx_backend import mjx
from openral_mjx.scenes.so101_box import So101BoxOptions, compose

OPTIONS = So101BoxOptions()
STEPS = 400  # 0.8 s at 2 ms
# (radial offset of the tube's axis from the hole's (m), direction (deg, block frame; the slot
# opens towards 0 deg), whether the tube must drop in)
CASES = [
    (0.0, 0.0, True),
    *[(0.0004, a, True) for a in (0.0, 45.0, 90.0, 180.0, 270.0)],
    *[(0.0007, a, False) for a in (45.0, 90.0, 180.0, 270.0)],
    *[(0.001, a, False) for a in (0.0, 90.0, 180.0)],
]


def fit_rig() -> mujoco.MjModel:
    """The scene's block and tube alone: block welded at the origin, tube on a z slide."""
    spec = compose(OPTIONS)
    spec.delete(spec.body("base"))  # the robot
    for actuator in list(spec.actuators):
        spec.delete(actuator)
    spec.delete(spec.joint("block_joint"))
    spec.body("block").pos = [0.0, 0.0, OPTIONS.block_size[2] / 2]
    spec.delete(spec.joint("tube_joint"))
    spec.body("tube").add_joint(name="tube_z", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1])
    return spec.compile()


def start_positions() -> np.ndarray:
    """Tube centres: lower end 1 mm above the block's top face (0.5 mm above the rim)."""
    z = OPTIONS.block_size[2] + 0.001 + OPTIONS.tube_length / 2
    return np.array(
        [
            [off * math.cos(math.radians(a)), off * math.sin(math.radians(a)), z]
            for off, a, _ in CASES
        ]
    )


@pytest.fixture(scope="module")
def rig() -> mujoco.MjModel:
    return fit_rig()


def depth_below_top(lower_end_z: np.ndarray) -> np.ndarray:
    return OPTIONS.block_size[2] - lower_end_z


def c_lower_end(rig: mujoco.MjModel) -> np.ndarray:
    tube, end = rig.body("tube").id, rig.site("tube_end_a").id
    out = []
    for pos in start_positions():
        rig.body_pos[tube] = pos
        d = mujoco.MjData(rig)
        mujoco.mj_forward(rig, d)
        for _ in range(STEPS):
            mujoco.mj_step(rig, d)
        out.append(d.site_xpos[end, 2])
    return np.array(out)


def mjx_lower_end(rig: mujoco.MjModel) -> np.ndarray:
    tube, end = rig.body("tube").id, rig.site("tube_end_a").id
    mx = mjx.put_model(rig)

    def drop(pos):
        m = mx.replace(body_pos=mx.body_pos.at[tube].set(pos))
        d = mjx.forward(m, mjx.make_data(m))
        d = jax.lax.fori_loop(0, STEPS, lambda _, x: mjx.step(m, x), d)
        return d.site_xpos[end, 2]

    return np.asarray(jax.jit(jax.vmap(drop))(jnp.asarray(start_positions(), jnp.float32)))


@pytest.fixture(scope="module")
def c_depths(rig) -> np.ndarray:
    return depth_below_top(c_lower_end(rig))


@pytest.fixture(scope="module")
def mjx_depths(rig) -> np.ndarray:
    return depth_below_top(mjx_lower_end(rig))


@pytest.mark.parametrize("engine", ["c", "mjx"])
def test_tube_fits_the_hole_with_the_stated_clearance(engine, c_depths, mjx_depths):
    depths = c_depths if engine == "c" else mjx_depths
    height = OPTIONS.block_size[2]
    for (offset, angle, fits), depth in zip(CASES, depths, strict=True):
        case = f"{engine}: {offset * 1000:.1f} mm at {angle:.0f} deg, depth {depth * 1000:.2f} mm"
        if fits:
            # Through the hole onto the floor (soft contact: within 0.1 mm of it).
            assert depth > height - 0.0001, case
        else:
            # Resting on the rim, its rounded end dipping in, short of the insertion depth.
            assert 0.005 < depth < OPTIONS.insertion_depth - 0.003, case


def test_mjx_rests_where_c_rests(c_depths, mjx_depths):
    """Float32 MJX and float64 C settle the tube at the same height to within 0.1 mm."""
    np.testing.assert_allclose(mjx_depths, c_depths, atol=1e-4)
