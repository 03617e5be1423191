"""The JAX chain kinematics against MuJoCo C: `mj_kinematics` poses and `mj_jacSite`."""

import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.physics.kinematics import site_kinematics


def test_site_pose_and_jacobian_match_mujoco(push_c):
    m = push_c.mj_model
    d = mujoco.MjData(m)
    site = push_c.ee_site_id
    fk = site_kinematics(m, site, push_c.robot_qpos_adr)
    rng = np.random.default_rng(0)
    lo, hi = m.jnt_range[push_c.robot_joint_ids].T
    jacp_ref, jacr_ref = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    for _ in range(20):
        q = rng.uniform(lo, hi)
        d.qpos[:] = m.qpos0
        d.qpos[push_c.robot_qpos_adr] = q
        mujoco.mj_forward(m, d)
        mujoco.mj_jacSite(m, d, jacp_ref, jacr_ref, site)
        pos, rot, jacp, jacr = fk(jnp.asarray(q, jnp.float32))
        dofs = push_c.robot_dof_adr
        # float32 chain of 6 bodies: errors of a few 1e-7 expected.
        np.testing.assert_allclose(pos, d.site_xpos[site], atol=1e-6)
        np.testing.assert_allclose(rot, d.site_xmat[site].reshape(3, 3), atol=1e-6)
        np.testing.assert_allclose(jacp, jacp_ref[:, dofs], atol=1e-6)
        np.testing.assert_allclose(jacr, jacr_ref[:, dofs], atol=1e-6)
