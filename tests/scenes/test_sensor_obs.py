"""Sensor observations end to end: scene options, the C backend's pose readout feeding the ray
casts, a laser on a user robot with a mobile base, the depth policy in the loop, and the
episodes' frames saved beside the report."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from test_raycast import MOBILE, multiray

from openral_mjx import raycast
from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import run_evaluation
from openral_mjx.evaluation.frames import check_frames, load_frames, record_frames, save_frames
from openral_mjx.physics import PhysicsSettings
from openral_mjx.policies import make_policy
from openral_mjx.raycast.geoms import subtree
from openral_mjx.report import load_report, save_report
from openral_mjx.runner import run_seeds, seed_keys
from openral_mjx.scenes import make_scene

DEPTH = {"obs_depth_cameras": ["overhead", "wrist"], "obs_depth_size": [16, 10]}


@pytest.fixture(scope="module")
def box_depth_c():
    return make_scene("so101_box", DEPTH, backend="c", settings=PhysicsSettings(threads=2))


def _host_data(scene, bits: np.ndarray) -> mujoco.MjData:
    """MuJoCo C data of one env of the C backend's state, kinematics evaluated."""
    model = scene.backend.host_model
    d = mujoco.MjData(model)
    mujoco.mj_setState(model, d, bits.view(np.float64), mujoco.mjtState.mjSTATE_FULLPHYSICS)
    mujoco.mj_forward(model, d)
    return d


def test_depth_observation_on_the_c_backend(box_depth_c):
    """The C backend reads back the poses the cameras need (framepos/framequat sensors); the
    depth slices equal the ray cast on MuJoCo's own state, and mj_multiRay agrees."""
    scene = box_depth_c
    state = jax.jit(jax.vmap(scene.reset))(seed_keys(jnp.arange(2))[0])
    assert scene.obs_shapes["depth_overhead"] == (10, 16)
    for i in range(2):
        d = _host_data(scene, np.asarray(state.physics.data[i]))
        for cam in ("overhead", "wrist"):
            start, size = scene.obs_layout[f"depth_{cam}"]
            got = np.asarray(state.obs[i, start : start + size]).reshape(10, 16)
            sensor = raycast.DepthSpec(cam, width=16, height=10, max_range_m=1.0).build(
                scene.mj_model
            )
            want, _ = raycast.depth_image(
                sensor, jnp.asarray(d.xpos, jnp.float32), jnp.asarray(d.xquat, jnp.float32)
            )
            np.testing.assert_allclose(got, want, atol=1e-5)
            c = sensor.cam_id
            t, _ = multiray(
                scene.mj_model, d, d.cam_xpos[c], sensor.dirs @ d.cam_xmat[c].reshape(3, 3).T
            )
            z = (t * sensor.optical_dirs[:, 2]).reshape(10, 16)
            np.testing.assert_allclose(got, np.where(z <= 1.0, z, 1.0), atol=1e-4)


def test_laser_observation_on_a_mobile_base():
    """`tabletop_push` with a user robot on a mobile base and a laser on it: the scan sees the
    cube (its beams 1.5 cm above the table), never the robot itself, as mj_multiRay does with
    the robot hidden."""
    options = {
        "robot_mjcf": str(MOBILE),
        "obs_laser_frame": "base_link",
        "obs_laser_height": 0.015,
        "obs_laser_beams": 90,
        "obs_laser_range": 2.0,
    }
    scene = make_scene("tabletop_push", options, backend="c", settings=PhysicsSettings(threads=1))
    assert scene.obs_shapes["scan"] == (90,)
    state = jax.jit(jax.vmap(scene.reset))(seed_keys(jnp.arange(2))[0])
    model = scene.mj_model
    robot = subtree(model, [model.body("base_link").id])
    for i in range(2):
        d = _host_data(scene, np.asarray(state.physics.data[i]))
        start, size = scene.obs_layout["scan"]
        scan = np.asarray(state.obs[i, start : start + size])
        base = model.body("base_link").id
        origin = d.xpos[base] + np.array([0.0, 0.0, 0.015])
        angles = -np.pi + np.arange(90) * 2 * np.pi / 90
        dirs = np.stack([np.cos(angles), np.sin(angles), np.zeros(90)], axis=1)
        t, geom = multiray(model, d, origin, dirs, hidden_bodies=robot)
        np.testing.assert_allclose(scan, np.minimum(t, 2.0), atol=1e-4)
        assert {model.geom(int(g)).name for g in geom if g >= 0} == {"cube"}
        assert scan.min() > 0.08  # the chassis (8 cm to its front) is not seen


def test_unknown_camera_is_a_build_time_error():
    with pytest.raises(ConfigError, match="unknown camera 'ceiling'; valid: overhead, wrist"):
        make_scene("so101_box", {"obs_depth_cameras": ["ceiling"]}, backend="c")
    with pytest.raises(ConfigError, match="no body or site named 'chassis'"):
        make_scene("tabletop_push", {"obs_laser_frame": "chassis"}, backend="c")


@pytest.mark.heavy
def test_depth_policy_in_the_loop_and_frames_beside_the_report(box_depth_c, tmp_path):
    """The random-weight CNN acts on the depth image under one jit; the first episodes' frames,
    re-simulated after the run, are bit for bit the depth slices of the observations the policy
    chose its actions from, cut at each episode's end, and round-trip through the `.npz`."""
    scene = box_depth_c
    evaluation = run_evaluation(scene, "depth_cnn", n_envs=2, max_steps=5, seed=3)
    report = evaluation.report
    assert report.n_episodes == 2 and not report.diverged
    arrays = record_frames(evaluation, 1, "r.frames.npz")
    first, second = report.episodes
    assert second.frames is None
    assert [(f["sensor"], f["reproduced"]) for f in first.frames] == [
        ("depth_overhead", True),
        ("depth_wrist", True),
    ]
    # What the policy observed at each step, from the runner's own observation trace.
    policy = make_policy("depth_cnn", scene)
    traced, _ = run_seeds(
        scene, policy, evaluation.params, seeds=np.array([3, 4]), n_envs=2, max_steps=5,
        record=("obs",),
    )  # fmt: skip
    steps = first.steps
    for cam in ("overhead", "wrist"):
        start, size = scene.obs_layout[f"depth_{cam}"]
        frames = arrays[f"seed3/depth_{cam}"]
        assert frames.shape == (steps + 1, 10, 16) and frames.dtype == np.float32
        seen = traced["obs"][0, :, start : start + size].reshape(-1, 10, 16)
        n = min(steps + 1, 5)  # frames run to the end state, observations to the last action
        np.testing.assert_array_equal(frames[:n], seen[:n])
        assert frames.min() < 0.9  # the floor and objects, not an empty image

    path = tmp_path / "r.json"
    save_frames(tmp_path / "r.frames.npz", arrays)
    save_report(report, path)
    loaded = load_frames(path, load_report(path))
    assert set(loaded) == {3}
    np.testing.assert_array_equal(loaded[3]["depth_wrist"], arrays["seed3/depth_wrist"])
    (tmp_path / "r.frames.npz").unlink()
    with pytest.raises(ConfigError, match="does not exist"):
        load_frames(path, load_report(path))


def test_depth_policy_reads_the_image(box_depth_c):
    policy = make_policy("depth_cnn", box_depth_c)
    spec = jax.ShapeDtypeStruct((box_depth_c.observation_size,), jnp.float32)
    params, state = policy.init(jax.random.PRNGKey(0), spec)
    obs = jnp.full(spec.shape, 0.5, jnp.float32)
    start, size = box_depth_c.obs_layout["depth_overhead"]
    other = obs.at[start : start + size // 2].set(0.2)
    a, _ = policy.act(params, state, obs, jax.random.PRNGKey(1))
    b, _ = policy.act(params, state, other, jax.random.PRNGKey(1))
    low, high = box_depth_c.action_bounds()
    assert not np.allclose(a, b) and bool(jnp.all((a >= low) & (a <= high)))
    with pytest.raises(ConfigError, match="needs a depth image in the observation"):
        make_policy("depth_cnn", make_scene("so101_box", backend="c"))


def test_frames_need_sensors(push_c, box_depth_c):
    with pytest.raises(ConfigError, match="scene 'tabletop_push' observes no sensors"):
        check_frames(push_c, 1)
    with pytest.raises(ConfigError, match="frames must be >= 0, got -1"):
        check_frames(box_depth_c, -1)
    check_frames(push_c, 0)
