"""`physics.base`: what every backend shares."""

from __future__ import annotations

import mujoco
import numpy as np

from openral_mjx.physics.base import reference_qpos

BOXES = """
<mujoco>
  <worldbody>
    <geom type="plane" size="1 1 0.1"/>
    <body name="a"><freejoint/><geom type="box" size="0.05 0.05 0.05"/></body>
    <body name="b"><freejoint/><geom type="box" size="0.05 0.05 0.05"/></body>
  </worldbody>
  {keys}
</mujoco>
"""
APART = "0.3 0 0.05 1 0 0 0 -0.3 0 0.05 1 0 0 0"


def _contacts(m: mujoco.MjModel, qpos: np.ndarray) -> int:
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_forward(m, d)
    return d.ncon


def test_reference_pose_is_the_first_keyframe_else_qpos0():
    """Two boxes that start inside each other at the origin (as LIBERO's objects do): without
    a keyframe the reference is that pile-up, with one it is the keyframe's resting pose."""
    piled = mujoco.MjModel.from_xml_string(BOXES.format(keys=""))
    np.testing.assert_array_equal(reference_qpos(piled), piled.qpos0)
    keyed = mujoco.MjModel.from_xml_string(
        BOXES.format(keys=f'<keyframe><key qpos="{APART}"/><key qpos="{APART}"/></keyframe>')
    )
    np.testing.assert_array_equal(reference_qpos(keyed), keyed.key_qpos[0])
    assert _contacts(keyed, reference_qpos(keyed)) < _contacts(piled, reference_qpos(piled))
