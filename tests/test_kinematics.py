"""The JAX chain kinematics against MuJoCo C's forward kinematics."""

import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.physics.kinematics import site_kinematics


def test_site_pose_matches_mujoco(push_c):
    m = push_c.mj_model
    d = mujoco.MjData(m)
    fk = site_kinematics(m, push_c.ee_site_id, push_c.robot_qpos_adr)
    rng = np.random.default_rng(0)
    lo, hi = m.jnt_range[[m.joint(n).id for n in push_c.robot_joint_names]].T
    for _ in range(20):
        q = rng.uniform(lo, hi)
        d.qpos[:] = m.qpos0
        d.qpos[push_c.robot_qpos_adr] = q
        mujoco.mj_kinematics(m, d)
        pos, rot = fk(jnp.asarray(q, jnp.float32))
        # float32 chain of 6 bodies: a few 1e-7 m expected.
        np.testing.assert_allclose(pos, d.site_xpos[push_c.ee_site_id], atol=1e-6)
        np.testing.assert_allclose(rot, d.site_xmat[push_c.ee_site_id].reshape(3, 3), atol=1e-6)
