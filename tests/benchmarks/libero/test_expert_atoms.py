"""What `libero-expert` plays of a LIBERO goal, in which order, and what its ``expert``
observation entry holds per atom: pure functions of the goal's atoms (no LIBERO needed)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from openral_mjx.benchmarks.libero.export import (
    ATOM_SIZE,
    EXPERT_SIZE,
    closes,
    expert_atoms,
    expert_entry,
    expert_ids,
)


def _joint(name: str, threshold: float, above: bool) -> dict:
    return {"kind": "joints", "joints": [name], "threshold": [threshold], "above": [above]}


SHUT = _joint("drawer", 0.0, True)  # LIBERO's Close of a drawer: q > 0
OPEN = _joint("drawer", -0.14, False)  # Open: q <= -0.14
ON = _joint("knob", 0.5, True)  # TurnOn: q > 0.5
PUT = {"kind": "in_site", "obj": "bowl", "site_body": "drawer_body"}


def test_what_opens_comes_first_and_what_closes_last() -> None:
    assert closes(SHUT) and not closes(OPEN) and not closes(ON)
    assert expert_atoms([SHUT, PUT]) == [PUT, SHUT]  # the bowl in, then the drawer shut
    assert expert_atoms([PUT, OPEN]) == [OPEN, PUT]
    assert expert_atoms([PUT, PUT, ON]) == [ON, PUT, PUT]
    assert expert_atoms([{"kind": "true"}, PUT]) == [PUT]


def test_a_joint_atom_s_row_holds_the_moving_body_s_pose_and_the_joint() -> None:
    bodies = {"bowl": 1, "drawer_body": 2, "knob_body": 3}
    model = SimpleNamespace(
        joint=lambda n: SimpleNamespace(bodyid=[3], qposadr=[5]),
        body=lambda i: SimpleNamespace(name={3: "knob_body"}[i]),
    )
    ids = expert_ids([PUT, ON], model, bodies.__getitem__)
    assert ids == [(3, 3, 5), (1, 2, -1)]  # the knob first (it turns on)
    rng = np.random.default_rng(0)
    pos, quat, qpos = rng.normal(size=(4, 3)), rng.normal(size=(4, 4)), rng.normal(size=7)
    entry = expert_entry(pos, quat, qpos, ids)
    assert entry.shape == (EXPERT_SIZE,) and entry.dtype == np.float32
    knob, bowl, empty = entry[:ATOM_SIZE], entry[ATOM_SIZE : 2 * ATOM_SIZE], entry[2 * ATOM_SIZE :]
    np.testing.assert_array_equal(knob[:3], pos[3].astype(np.float32))
    np.testing.assert_array_equal(knob[3:6], np.array([qpos[5], 0, 0], np.float32))
    np.testing.assert_array_equal(knob[6:], quat[3].astype(np.float32))
    np.testing.assert_array_equal(bowl[:6], np.concatenate([pos[1], pos[2]]).astype(np.float32))
    np.testing.assert_array_equal(bowl[6:], quat[2].astype(np.float32))
    assert not empty.any()


KNOB = """
<mujoco>
  <worldbody>
    <body name="stove" pos="0.1 0.2 0.9">
      <geom type="box" size="0.1 0.1 0.01"/>
      <body name="knob" pos="0 0 0.01">
        <joint name="knob" type="hinge" axis="0 0 1" range="-0.005 2.1"/>
        <geom type="box" size="0.006 0.045 0.012" pos="0 0 0.025"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_a_knob_is_pushed_at_its_bar_however_far_it_starts_turned() -> None:
    """The contact point (in the knob's frame) is found with the joint at zero: the bar's end,
    on the bar, whether the knob starts at 0 or turned 0.98 rad (a knob to turn off). Found in
    the turned pose, the world-axis bounds' face centre lay 1.5 cm off the bar."""
    import mujoco

    from openral_mjx.benchmarks.libero.expert import PUSH, _joint_plan

    m = mujoco.MjModel.from_xml_string(KNOB)
    points = []
    for q in (0.0, 0.98):
        d = mujoco.MjData(m)
        d.qpos[0] = q
        mujoco.mj_kinematics(m, d)
        plan = _joint_plan(m, d, _joint("knob", 0.0, False), yaw=0.0)
        assert plan["kind"] == PUSH and plan["sign"] == -1.0
        points.append(plan["point"])
    np.testing.assert_allclose(points[0], points[1], atol=1e-9)
    assert abs(points[0][0]) < 1e-9 and 0.03 < abs(points[0][1]) < 0.045  # on the bar, inset
