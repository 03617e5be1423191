"""MuJoCo's warnings are counted by kind, not printed, and no `MUJOCO_LOG.TXT` is written."""

from __future__ import annotations

import mujoco

from openral_mjx.physics.mj_warnings import count_warnings, format_warnings, warning_kind

# A hinge with negative damping: its velocity grows without bound until MuJoCo finds its
# acceleration bad, warns "Nan, Inf or huge value in QACC" and resets the state (which then
# diverges again). It prints the warning once per MjData: each call below is one message.
UNSTABLE = """
<mujoco>
  <worldbody>
    <body>
      <joint type="hinge" damping="-50"/>
      <geom type="capsule" size="0.02" fromto="0 0 0 0.2 0 0" mass="0.1"/>
    </body>
  </worldbody>
</mujoco>
"""


def diverge(steps: int = 300) -> int:
    """Step the unstable model; how many times MuJoCo found its acceleration bad."""
    model = mujoco.MjModel.from_xml_string(UNSTABLE)
    data = mujoco.MjData(model)
    data.qvel[0] = 1.0
    bad = 0
    for _ in range(steps):
        mujoco.mj_step(model, data)
        bad += data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number
    return bad


def test_warnings_are_counted_not_printed_nor_logged(tmp_path, monkeypatch, capfd):
    monkeypatch.chdir(tmp_path)
    before = mujoco.get_mju_user_warning()
    with count_warnings() as outer:
        with count_warnings() as inner:
            assert all(diverge() > 1 for _ in range(3))
        assert diverge() > 1
    assert mujoco.get_mju_user_warning() is before  # the previous handler is back
    assert inner == {"BADQACC": 3}
    assert outer == {"BADQACC": 4}  # nested counters both count
    out, err = capfd.readouterr()
    assert "QACC" not in out + err
    assert list(tmp_path.iterdir()) == []


def test_kinds_from_messages():
    text = mujoco.mju_warningText(int(mujoco.mjtWarning.mjWARN_CONTACTFULL), 123)
    assert warning_kind(text) == "CONTACTFULL"
    assert warning_kind(mujoco.mju_warningText(int(mujoco.mjtWarning.mjWARN_BADQVEL), 7)) == (
        "BADQVEL"
    )
    assert warning_kind("something else") == "OTHER"
    assert format_warnings({"BADQACC": 1200, "CONTACTFULL": 3}) == "BADQACC 1,200, CONTACTFULL 3"
    assert format_warnings({}) == ""
