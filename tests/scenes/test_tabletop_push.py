"""tabletop_push: composition, reset sampling, the success predicate on hand-placed cubes."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.runner import make_factor_fn
from openral_mjx.scenes import make_scene


def test_layout_and_sizes(push_c):
    layout = push_c.obs_layout
    assert push_c.observation_size == sum(size for _, size in layout.values())
    assert push_c.action_size == push_c.mj_model.nu == 6
    assert push_c.mj_model.nmat >= 1  # mjx.ray needs a material


def test_reset_is_a_function_of_the_key(push_c):
    reset = jax.jit(push_c.reset)
    a, b = reset(jax.random.PRNGKey(3)), reset(jax.random.PRNGKey(3))
    c = reset(jax.random.PRNGKey(4))
    np.testing.assert_array_equal(a.obs, b.obs)
    assert not np.array_equal(a.obs, c.obs)


def test_reset_samples_within_ranges(push_c):
    o = push_c.options
    keys = jax.vmap(jax.random.PRNGKey)(jnp.arange(500))
    cube, goal = jax.vmap(push_c.sample_episode)(keys)
    cube, goal = np.asarray(cube), np.asarray(goal)
    assert (cube[:, 0] >= o.cube_spawn_x[0]).all() and (cube[:, 0] <= o.cube_spawn_x[1]).all()
    assert (cube[:, 1] >= o.cube_spawn_y[0]).all() and (cube[:, 1] <= o.cube_spawn_y[1]).all()
    assert (goal[:, 0] >= o.goal_region_x[0] - 1e-6).all()
    assert (goal[:, 0] <= o.goal_region_x[1] + 1e-6).all()
    # The goal never starts under the cube (so doing nothing cannot succeed).
    assert (np.linalg.norm(goal - cube[:, :2], axis=1) > o.goal_radius).mean() > 0.99


def test_factors_are_bit_identical_at_any_batch_size(push_c):
    """A seed's factors do not depend on the batch it runs in (see `make_factor_fn`)."""
    factor_fn = make_factor_fn(push_c)
    seeds = jnp.arange(21, dtype=jnp.int32)
    whole = factor_fn(seeds)
    for size in (1, 7):  # the scalar code path, and vectors with a remainder
        for start in range(0, 21, size):
            part = factor_fn(seeds[start : start + size])
            for name, values in whole.items():
                np.testing.assert_array_equal(part[name], values[start : start + size], name)
    angle = np.asarray(whole["push_face_angle"])
    assert angle.min() >= 0 and angle.max() <= np.pi / 4 + 1e-6


def _placed(scene, cube_xyz, goal_xy, cube_vel=(0.0, 0.0, 0.0)):
    """Evaluate the task on a hand-placed cube (robot at home) after one forward pass."""
    state = scene.reset(jax.random.PRNGKey(0))
    qpos = np.asarray(state.physics.quantities.qpos).copy()
    qvel = np.zeros(scene.mj_model.nv, np.float32)
    a, v = scene.cube_qpos_adr, scene.cube_dof_adr
    qpos[a : a + 7] = [*cube_xyz, 1, 0, 0, 0]
    qvel[v : v + 3] = cube_vel
    physics = scene.backend.init(jnp.asarray(qpos), jnp.asarray(qvel))
    state = state.replace(info={"goal_xy": jnp.asarray(goal_xy, jnp.float32)})
    return scene._evaluate(state, physics)


@pytest.mark.parametrize(
    "name,offset,dz,vel,expected",
    [
        ("on goal", (0.0, 0.0), 0.0, 0.0, True),
        ("inside radius", (0.012, -0.012), 0.0, 0.0, True),
        ("off goal", (0.03, 0.0), 0.0, 0.0, False),
        ("lifted above goal", (0.0, 0.0), 0.05, 0.0, False),
        ("sliding across goal", (0.0, 0.0), 0.0, 0.3, False),
    ],
)
def test_success_predicate(push_c, name, offset, dz, vel, expected):
    goal = np.array([0.22, 0.03])
    z = push_c.cube_rest_z + dz
    s = _placed(push_c, (goal[0] + offset[0], goal[1] + offset[1], z), goal, (vel, 0, 0))
    assert bool(s.metrics["success"]) is expected, name
    assert bool(s.done) is expected


def test_cube_fallen_off_table_is_not_success(push_c):
    # On the floor, directly below a goal placed at the table's edge.
    o = push_c.options
    edge_x = o.table_center[0] + o.table_size[0] / 2 + 0.05
    s = _placed(push_c, (edge_x, 0.0, o.cube_size / 2), (edge_x, 0.0))
    assert not bool(s.metrics["success"])


def test_unknown_option_is_rejected():
    with pytest.raises(ConfigError, match="goal_radiuss"):
        make_scene("tabletop_push", {"goal_radiuss": 0.1}, backend="c")
    with pytest.raises(ConfigError, match="goal_radius"):
        make_scene("tabletop_push", {"goal_radius": -1.0}, backend="c")


def test_config_yaml_matches_defaults():
    from pathlib import Path

    from openral_mjx.core.options import from_mapping, load_yaml
    from openral_mjx.scenes import TabletopPushOptions

    path = Path(__file__).parents[2] / "configs" / "tabletop_push.yaml"
    assert from_mapping(TabletopPushOptions, load_yaml(path)) == TabletopPushOptions()


def test_user_mjcf_robot(tmp_path):
    xml = tmp_path / "arm.xml"
    xml.write_text("""<mujoco><worldbody><body name="b"><joint name="j1" axis="0 0 1"/>
      <geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02"/>
      <body pos="0.2 0 0"><joint name="j2" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.1" size="0.02"/>
      <site name="tip" pos="0 0 -0.1"/></body></body></worldbody>
      <actuator><position joint="j1" kp="10" ctrlrange="-1 1"/>
      <position joint="j2" kp="10" ctrlrange="-1 1"/></actuator></mujoco>""")
    scene = make_scene("tabletop_push", {"robot_mjcf": str(xml), "ee_site": "tip"}, backend="c")
    assert scene.action_size == 2 and scene.observation_size == 2 * 2 + 3 + 3 + 4 + 2
    with pytest.raises(ConfigError, match=r"'hand'.*valid: tip"):
        make_scene("tabletop_push", {"robot_mjcf": str(xml), "ee_site": "hand"}, backend="c")
