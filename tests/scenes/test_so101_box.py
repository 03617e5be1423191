"""so101_box: composition, cameras, reset layout, the success predicate on hand-placed tubes,
options and the fixed robot, and the scripted inserter against the zero policy (MuJoCo C)."""

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.options import from_mapping, load_yaml
from openral_mjx.physics import PhysicsSettings
from openral_mjx.policies import make_policy
from openral_mjx.runner import run_seeds
from openral_mjx.scenes import So101Box, So101BoxOptions, make_scene


def test_layout_sizes_and_contact_budget(box_c):
    m = box_c.mj_model
    assert box_c.observation_size == sum(size for _, size in box_c.obs_layout.values())
    assert box_c.action_size == m.nu == 6
    assert m.nmat >= 1  # mjx.ray needs a material
    # Only pairs MJX collides with cheap primitives: no box-box, no mesh, no cylinder-box.
    from mujoco.mjx._src import collision_driver

    types = {tuple(int(t) for t in k.types) for k in collision_driver._geom_groups(m)}
    box, mesh, cylinder = 6, 7, 5
    assert (box, box) not in types and (cylinder, box) not in types
    assert not any(mesh in t for t in types)


def test_cameras_carry_the_option_intrinsics(box_c):
    o, m = box_c.options, box_c.mj_model
    for name in ("overhead", "wrist"):
        cam = m.camera(name)
        width, height = getattr(o, f"{name}_camera_resolution")
        fy = getattr(o, f"{name}_camera_focal")[1]
        assert tuple(m.cam_resolution[cam.id]) == (width, height)
        # Vertical field of view of a pinhole with focal length fy (pixels).
        assert m.cam_fovy[cam.id] == pytest.approx(2 * math.degrees(math.atan(height / 2 / fy)))
    assert m.body(m.cam_bodyid[m.camera("wrist").id]).name == "gripper"
    # The overhead camera sees the whole arena floor.
    fx, fy = o.overhead_camera_focal
    w, h = o.overhead_camera_resolution
    z = o.overhead_camera_pos[2]
    assert z * w / 2 / fx >= o.arena_width / 2 and z * h / 2 / fy >= o.arena_depth / 2


def test_reset_is_a_function_of_the_key(box_c):
    reset = jax.jit(box_c.reset)
    a, b, c = (reset(jax.random.PRNGKey(s)) for s in (3, 3, 4))
    np.testing.assert_array_equal(a.obs, b.obs)
    assert not np.array_equal(a.obs, c.obs)


def _check_layouts(options: So101BoxOptions, blocks: np.ndarray, tubes: np.ndarray) -> None:
    o = options
    for obj, xy in (("block", blocks), ("tube", tubes)):
        for i, axis in enumerate("xy"):
            lo, hi = getattr(o, f"{obj}_spawn_{axis}")
            assert (xy[:, i] >= lo - 1e-6).all() and (xy[:, i] <= hi + 1e-6).all()
    r_block, r_tube = o.block_radius, o.tube_diameter / 2
    gap = np.linalg.norm(blocks[:, :2] - tubes[:, :2], axis=1) - r_block - r_tube
    assert (gap >= o.spawn_gap - 1e-6).all(), gap.min()
    assert (np.linalg.norm(blocks[:, :2], axis=1) >= o.robot_keepout + r_block - 1e-6).all()
    assert (np.linalg.norm(tubes[:, :2], axis=1) >= o.robot_keepout + r_tube - 1e-6).all()


def test_reset_layouts_stay_in_range_and_apart(box_c):
    keys = jax.vmap(jax.random.PRNGKey)(jnp.arange(2000))
    blocks, tubes = (np.asarray(x) for x in jax.vmap(box_c.sample_layout)(keys))
    _check_layouts(box_c.options, blocks, tubes)
    # Yaws cover their ranges; block and tube are drawn independently.
    assert blocks[:, 2].min() < -3.0 and blocks[:, 2].max() > 3.0
    assert abs(np.corrcoef(blocks[:, 0], tubes[:, 0])[0, 1]) < 0.2
    # The reset state puts them there, resting on the floor.
    state = jax.vmap(box_c.reset)(keys[:8])
    pos = np.asarray(state.physics.quantities.body_pos)
    np.testing.assert_allclose(pos[:, 1, :2], blocks[:8, :2], atol=1e-6)
    np.testing.assert_allclose(pos[:, 0, :2], tubes[:8, :2], atol=1e-6)
    np.testing.assert_allclose(pos[:, 1, 2], box_c.options.block_size[2] / 2, atol=1e-6)
    np.testing.assert_allclose(pos[:, 0, 2], box_c.options.tube_length / 2, atol=1e-6)


def test_crowded_ranges_fall_back_to_a_valid_layout():
    # Ranges where most random draws overlap: the fallback corners must keep every rule.
    o = So101BoxOptions(
        block_spawn_x=(0.17, 0.2),
        block_spawn_y=(-0.03, 0.03),
        tube_spawn_x=(0.17, 0.2),
        tube_spawn_y=(-0.06, 0.06),
    )
    scene = So101Box(o, backend="c", settings=PhysicsSettings(threads=1))
    keys = jax.vmap(jax.random.PRNGKey)(jnp.arange(2000))
    blocks, tubes = (np.asarray(x) for x in jax.vmap(scene.sample_layout)(keys))
    _check_layouts(o, blocks, tubes)
    fallback_block, fallback_tube = o.fallback_layout()
    used = np.all(np.isclose(blocks[:, :2], fallback_block), axis=1)
    assert used.any() and np.all(np.isclose(tubes[used, :2], fallback_tube))


def test_impossible_ranges_are_a_config_error():
    with pytest.raises(ConfigError, match="no room"):
        So101BoxOptions(
            block_spawn_x=(0.2, 0.2),
            block_spawn_y=(0.0, 0.0),
            tube_spawn_x=(0.2, 0.21),
            tube_spawn_y=(0.0, 0.01),
        )


def _axis_quat(tilt: float, azimuth: float = 0.0) -> np.ndarray:
    """Quaternion turning +z by `tilt` towards the horizontal direction `azimuth`."""
    axis = np.array([-math.sin(azimuth), math.cos(azimuth), 0.0])
    return np.array([math.cos(tilt / 2), *(math.sin(tilt / 2) * axis)])


def _placed(scene, block_xy, block_yaw, lower_end, tilt=0.0, azimuth=0.0, flipped=False):
    """Evaluate the task with the block and the tube placed by hand (one forward pass).

    `lower_end` is the world position of the tube's lower end; the tube's axis leans by `tilt`
    towards `azimuth`; `flipped` puts the tube upside down (its other end lower).
    """
    o = scene.options
    state = scene.reset(jax.random.PRNGKey(0))
    qpos = np.asarray(state.physics.quantities.qpos).copy()
    a, b = scene.block_qpos_adr, scene.tube_qpos_adr
    qpos[a : a + 3] = [*block_xy, o.block_size[2] / 2]
    qpos[a + 3 : a + 7] = [math.cos(block_yaw / 2), 0, 0, math.sin(block_yaw / 2)]
    quat = _axis_quat(tilt + (math.pi if flipped else 0.0), azimuth)
    up = np.array(
        [math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth), math.cos(tilt)]
    )
    qpos[b : b + 3] = np.asarray(lower_end) + up * o.tube_length / 2
    qpos[b + 3 : b + 7] = quat
    physics = scene.backend.init(jnp.asarray(qpos), jnp.zeros(scene.mj_model.nv))
    return scene._evaluate(state, physics)


BLOCK = (0.2, 0.03)


def _in_hole(depth: float, offset: tuple[float, float] = (0.0, 0.0), yaw: float = 0.0):
    """A world point `depth` below the block's top face, `offset` (block frame) off its axis."""
    c, s = math.cos(yaw), math.sin(yaw)
    return (
        BLOCK[0] + c * offset[0] - s * offset[1],
        BLOCK[1] + s * offset[0] + c * offset[1],
        0.02 - depth,
    )


@pytest.mark.parametrize(
    "name,yaw,lower,tilt,flipped,expected",
    [
        ("fully in", 0.0, _in_hole(0.02), 0.0, False, True),
        ("fully in, upside down", 0.0, _in_hole(0.02), 0.0, True, True),
        (
            "fully in, block yawed, off axis",
            0.7,
            _in_hole(0.02, (0.0004, 0.0), 0.7),
            0.0,
            False,
            True,
        ),
        ("just deep enough", 0.0, _in_hole(0.0151), 0.0, False, True),
        ("half in", 0.0, _in_hole(0.008), 0.0, False, False),
        ("just too shallow", 0.0, _in_hole(0.0149), 0.0, False, False),
        ("tilted in, within tolerance", 0.0, _in_hole(0.018), math.radians(3), False, True),
        ("tilted in", 0.0, _in_hole(0.018), math.radians(10), False, False),
        ("beside the hole", 0.0, (BLOCK[0] + 0.07, BLOCK[1], 0.0), 0.0, False, False),
        ("in the slot only", 1.2, _in_hole(0.018, (0.0115 + 0.0025, 0.0), 1.2), 0.0, False, False),
        ("at the hole's edge", 0.0, _in_hole(0.018, (0.0, 0.0114)), 0.0, False, True),
        ("past the hole's edge", 0.0, _in_hole(0.018, (0.0, 0.0116)), 0.0, False, False),
    ],
)
def test_success_predicate(box_c, name, yaw, lower, tilt, flipped, expected):
    s = _placed(box_c, BLOCK, yaw, lower, tilt=tilt, flipped=flipped)
    assert bool(s.metrics["success"]) is expected, name
    assert bool(s.done) is expected


def test_tube_lying_on_the_block_is_not_success(box_c):
    # Axis horizontal, resting across the top face with its lower side on it.
    r = box_c.options.tube_diameter / 2
    end = (BLOCK[0] - 0.045, BLOCK[1], 0.02 + r)
    s = _placed(box_c, BLOCK, 0.0, end, tilt=math.pi / 2, azimuth=0.0)
    assert not bool(s.metrics["success"])
    centre = np.asarray(s.physics.quantities.body_pos[0])
    np.testing.assert_allclose(centre[:2], BLOCK, atol=1e-6)  # its middle right over the hole


def test_episode_factors(box_c):
    state = box_c.reset(jax.random.PRNGKey(5))
    block, tube = box_c.sample_layout(jax.random.PRNGKey(5))
    f = box_c.episode_factors(state)
    assert float(f["tube_block_distance"]) == pytest.approx(
        float(np.linalg.norm(np.asarray(block[:2] - tube[:2]))), abs=1e-6
    )
    assert float(f["block_yaw"]) == pytest.approx(float(block[2]), abs=1e-5)
    assert float(f["tube_reach"]) == pytest.approx(float(np.linalg.norm(tube[:2])), abs=1e-6)


def test_options_are_validated():
    with pytest.raises(ConfigError, match="hole_diametr"):
        make_scene("so101_box", {"hole_diametr": 0.03}, backend="c")
    with pytest.raises(ConfigError, match=r"tube_diameter=0\.025 must be < hole_diameter"):
        So101BoxOptions(tube_diameter=0.025)
    with pytest.raises(ConfigError, match="block_spawn_x"):
        So101BoxOptions(block_spawn_x=(0.2, 0.1))
    with pytest.raises(ConfigError, match="inside the arena"):
        So101BoxOptions(tube_spawn_y=(-0.6, 0.0))
    with pytest.raises(ConfigError, match="insertion_depth"):
        So101BoxOptions(insertion_depth=0.03)


def test_fixed_robot():
    for overrides, asked in (
        ({"robot": "ur5"}, "'ur5'"),
        ({"robot_mjcf": "a/arm.xml"}, "'mjcf:arm.xml'"),
    ):
        with pytest.raises(ConfigError, match=f"requires robot 'so101', not {asked}"):
            make_scene("so101_box", overrides, backend="c")


def test_config_yaml_matches_defaults():
    path = Path(__file__).parents[2] / "configs" / "so101_box.yaml"
    assert from_mapping(So101BoxOptions, load_yaml(path)) == So101BoxOptions()


STEPS = 220  # the scripted inserter succeeds within ~190 control steps


@pytest.fixture(scope="module")
def scripted_runs(box_c):
    pol = make_policy("scripted", box_c)
    batch, _ = run_seeds(box_c, pol, None, seeds=np.arange(12), n_envs=12, max_steps=STEPS)
    alone, _ = run_seeds(box_c, pol, None, seeds=np.array([7]), n_envs=1, max_steps=STEPS)
    return batch, alone


def test_scripted_inserter_succeeds(scripted_runs):
    batch, _ = scripted_runs
    assert batch["success"].sum() >= 10, batch["success"]
    assert not batch["diverged"].any()


def test_seed_gives_same_episode_at_any_batch_size(scripted_runs):
    batch, alone = scripted_runs
    for k in batch:
        np.testing.assert_array_equal(alone[k][0], batch[k][7], err_msg=k)


def test_zero_policy_never_succeeds(box_c):
    pol = make_policy("zero", box_c)
    arrays, _ = run_seeds(box_c, pol, None, seeds=np.arange(12), n_envs=12, max_steps=STEPS)
    assert not arrays["success"].any()
