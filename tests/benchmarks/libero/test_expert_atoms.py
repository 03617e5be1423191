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


def test_a_pick_s_approach_crosses_at_the_height_the_hand_starts_from() -> None:
    """After one atom's retreat the hand crosses to the next object at its own height, then
    comes down to the approach point: on the diagonal down from over the basket, a finger
    hooked the wall it had just let go over and lifted the basket away (`libero_10/1`: 2 of
    10 seeds, now 9). The first approach (the hand's hold is unset, zero) and one from below
    keep grasp + `ABOVE`."""
    import jax.numpy as jnp

    from openral_mjx.benchmarks.libero.expert import ABOVE, APPROACH, PICK, Plan, _pick_targets

    zero = np.zeros((1, 3), np.float32)
    plan = Plan(
        kind=np.array([PICK], np.int32),
        point=np.array([[0.0, 0.0, 0.01]], np.float32),
        site_pos=zero,
        release_z=np.array([0.1], np.float32),
        axis=zero,
        anchor=zero,
        slide=np.array([False]),
        yaw=np.zeros(1, np.float32),
        turn=np.zeros(1, bool),
        sign=np.zeros(1, np.float32),
        threshold=np.zeros(1, np.float32),
        press=np.zeros(1, np.float32),
        coverage="covered",
    )
    row = jnp.array([0.05, 0.06, 0.44, 0.0, 0.27, 0.43, 1.0, 0.0, 0.0, 0.0])  # object, target
    grasp = np.array([0.05, 0.06, 0.45])
    over = jnp.array([0.06, 0.07, 0.70])  # the hand, crossed: 1.4 cm from over the grasp
    for hold_z, at, want_z in (
        (0.70, None, 0.70),  # crossing from over the basket: level
        (0.70, over, 0.45 + ABOVE),  # crossed: down to the approach point
        (0.0, None, 0.45 + ABOVE),  # the first approach
        (0.50, None, 0.45 + ABOVE),  # from below the approach point
    ):
        hold = jnp.array([0.0, 0.27, hold_z])
        eef = hold if at is None else at
        target = np.asarray(_pick_targets(plan, row, jnp.int32(0), eef, hold)[APPROACH])
        np.testing.assert_allclose(target, [*grasp[:2], want_z], atol=1e-6)


def _box(low: list[float], high: list[float]) -> tuple[np.ndarray, np.ndarray]:
    return np.array(low), np.array(high)


# LIBERO's moka pot at its initial state, world-axis bounds relative to its origin (m): an
# octagonal body 8.2 cm across x, the spout on +y, the handle on -y, and the lid's knob
MOKA_POT = [
    _box([-0.025, -0.035, -0.066], [0.025, 0.031, 0.067]),  # body
    _box([-0.041, -0.03, -0.066], [-0.02, 0.005, 0.067]),  # body, a slanted side
    _box([0.019, -0.003, -0.066], [0.04, 0.032, 0.067]),  # body, a slanted side
    _box([-0.018, 0.03, 0.018], [0.018, 0.042, 0.067]),  # spout
    _box([-0.007, -0.091, 0.039], [0.007, -0.06, 0.068]),  # handle, top
    _box([-0.005, -0.005, 0.063], [0.005, 0.007, 0.086]),  # knob
]


def test_a_wide_object_with_a_knob_is_grasped_by_the_knob_with_the_fingertips_clear() -> None:
    """The moka pot is wider than the open fingers across both axes; on the closing axis
    (y) its rim is the spout, which the fingers closed on at an angle (`libero_10/2`: 0 of
    10 seeds). Its knob stands 1.8 cm over the rest: the grip site goes over the knob's
    middle, the fingertips `TIP_CLEAR` over the handle's top. A bowl, nothing standing
    above its rim, has no knob."""
    from openral_mjx.benchmarks.libero.expert import TIP, TIP_CLEAR, _knob

    y = np.array([0.0, 1.0, 0.0])
    point = _knob(MOKA_POT, y)
    np.testing.assert_allclose(point, [0.0, 0.001, 0.068 + TIP + TIP_CLEAR], atol=1e-9)
    bowl = [
        _box([-0.07, -0.07, 0.0], [0.07, -0.06, 0.05]),
        _box([-0.07, 0.06, 0.0], [0.07, 0.07, 0.05]),
    ]
    assert _knob(bowl, y) is None
    wide_lid = [*MOKA_POT[:-1], _box([-0.05, -0.05, 0.063], [0.05, 0.05, 0.086])]
    assert _knob(wide_lid, y) is None  # standing above the rest, but wider than the fingers


def test_objects_put_on_one_region_stand_side_by_side_along_their_narrow_axis() -> None:
    """Two moka pots put on one burner (`libero_10/8`) go `SIDE_GAP` apart along x, the axis
    they are narrower in (8.1 cm against 14.8 with spout and handle), centred on the region;
    the offset is in the region's body frame (here turned a quarter about z). Objects put
    `In` one container keep the same point, and a lone atom is untouched."""
    from openral_mjx.benchmarks.libero.expert import PICK, SIDE_GAP, _side_by_side

    def row(footprint: list[float]) -> dict:
        return {"kind": PICK, "site_pos": np.zeros(3), "footprint": np.array(footprint)}

    on = {"kind": "on_site", "site_body": "burner", "site_pos": [0.0, 0.0, 0.0]}
    into = {"kind": "in_site", "site_body": "basket", "site_pos": [0.0, 0.0, 0.07]}
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # body x = world y
    atoms = [on, on, into, into, {**on, "site_body": "plate"}]
    rows = [row([0.081, 0.148]), row([0.081, 0.148])] + [row([0.06, 0.06]) for _ in range(3)]
    _side_by_side(atoms, rows, lambda body: quarter if body == "burner" else np.eye(3))
    half = 0.081 / 2 + SIDE_GAP / 2
    world = [quarter @ rows[i]["site_pos"] for i in (0, 1)]
    np.testing.assert_allclose(world, [[-half, 0.0, 0.0], [half, 0.0, 0.0]], atol=1e-12)
    for i in (2, 3, 4):
        np.testing.assert_array_equal(rows[i]["site_pos"], np.zeros(3))


def test_a_pan_is_grasped_by_its_handle_near_the_body_with_the_hand_turned_across_it() -> None:
    """LIBERO's frying pan (20 cm across; boxes relative to its origin, at its initial state)
    sticks its handle out 12 cm along y, the fingers' closing axis: its rim there was the
    handle's end, which the fingers closed along (`libero_90/21`, `/45`: 0 of 10 seeds). The
    grasp goes `HANDLE_IN` from the handle's inner end, 1.5 cm below its top, and the plan
    turns the hand a quarter so the fingers close across it. A part that does not reach out
    past the rest (a bowl's rim) is no handle."""
    from openral_mjx.benchmarks.libero.expert import HANDLE_IN, _handle

    pan = [
        _box([-0.013, 0.126, 0.029], [0.013, 0.259, 0.059]),  # the handle
        _box([-0.015, 0.118, 0.015], [0.007, 0.141, 0.04]),  # its joint to the wall
        _box([-0.055, -0.055, 0.001], [0.055, 0.055, 0.013]),  # the bottom
        _box([-0.101, -0.016, 0.002], [-0.073, 0.026, 0.042]),  # walls
        _box([0.074, -0.02, 0.002], [0.103, 0.022, 0.042]),
        _box([-0.022, 0.083, 0.002], [0.02, 0.111, 0.042]),
        _box([-0.022, -0.097, 0.002], [0.021, -0.068, 0.042]),
    ]
    point, along, index = _handle(pan)
    np.testing.assert_allclose(point, [0.0, 0.126 + HANDLE_IN, 0.059 - 0.015], atol=1e-9)
    np.testing.assert_array_equal(along, [0.0, 1.0, 0.0])
    assert index == 0
    rim = [
        _box([-0.07, -0.07, 0.0], [0.07, -0.06, 0.05]),
        _box([-0.07, 0.06, 0.0], [0.07, 0.07, 0.05]),
    ]
    assert _handle(rim) is None
    assert _handle(pan[1:]) is None  # without the handle


def test_a_region_with_a_part_of_its_target_over_it_is_not_placed_into() -> None:
    """LIBERO's microwave (`libero_10/9`, world bounds at initial state 0): its inside, the
    region the mug goes `In`, lies under the microwave's top, 7.2 cm over the region's site;
    let down straight, the mug landed on the top (0 of 10 seeds). A basket's walls and a
    burner 1 cm over its site are no roof, nor is a top that does not reach over the site;
    a shut drawer's cabinet over it is."""
    from openral_mjx.benchmarks.libero.expert import _roofed

    microwave = [
        _box([-0.166, 0.268, 0.92], [-0.137, 0.467, 1.107]),  # the left wall
        _box([0.07, 0.268, 0.92], [0.179, 0.467, 1.107]),  # the control panel
        _box([-0.137, 0.436, 0.92], [0.07, 0.466, 1.107]),  # the back
        _box([-0.137, 0.268, 1.088], [0.07, 0.437, 1.107]),  # the top
        _box([-0.137, 0.268, 0.92], [0.07, 0.436, 0.944]),  # the floor
    ]
    inside = np.array([0.007, 0.366, 1.016])
    assert _roofed(microwave, inside)
    assert not _roofed(microwave[:3] + microwave[4:], inside)  # without its top
    assert not _roofed(microwave, inside + np.array([0.0, -0.2, 0.0]))  # in front of it
    basket = [
        _box([-0.1, -0.1, 0.0], [-0.09, 0.1, 0.08]),
        _box([0.09, -0.1, 0.0], [0.1, 0.1, 0.08]),
        _box([-0.1, -0.1, 0.0], [0.1, 0.1, 0.01]),
    ]
    assert not _roofed(basket, np.array([0.0, 0.0, 0.01]))
    burner = [_box([-0.05, -0.05, 0.01], [0.05, 0.05, 0.02])]
    assert not _roofed(burner, np.zeros(3))
    # `libero_goal/3`'s bowl goes `In` the cabinet's top drawer, which starts shut: the
    # cabinet's top (another body of the fixture than the drawer) lies 3.5 cm over its site
    cabinet_top = [_box([-0.092, -0.344, 1.125], [0.163, -0.156, 1.128])]
    assert _roofed(cabinet_top, np.array([0.036, -0.245, 1.091]))
