"""Videos: re-simulated episodes match the evaluated ones, frames show the recorded state, and
the MP4 has one frame per step at the panels' size."""

import dataclasses

import av
import jax
import mujoco
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import Evaluation
from openral_mjx.evaluation.replay import choose_seeds, trace_episodes
from openral_mjx.physics import gl as gl_module
from openral_mjx.runner import seed_keys
from openral_mjx.viz.video import (
    HEADER_H,
    PANEL_H,
    PANEL_W,
    episode_frames,
    episode_title,
    write_episode_video,
)


@pytest.fixture(scope="module")
def traces(scripted_eval):
    """A failed and a successful episode, re-simulated."""
    success = scripted_eval.arrays["success"]
    seeds = [int(np.flatnonzero(~success)[0]), int(np.flatnonzero(success)[0])]
    return trace_episodes(scripted_eval, seeds)


@pytest.fixture(scope="module")
def frames(traces, scripted_eval, gl):
    scene = scripted_eval.scene
    return [
        np.stack(list(episode_frames(scene, t, "front", gl, episode_title(scene, "scripted", t))))
        for t in traces
    ]


def sequential_sum(values: np.ndarray) -> np.float32:
    """float32 running sum in step order, as the runner accumulates it."""
    total = np.float32(0)
    for v in values.astype(np.float32):
        total = np.float32(total + v)
    return total


def test_resimulated_episodes_are_the_evaluated_ones(traces, scripted_eval):
    episodes = {e.metadata["seed"]: e for e in scripted_eval.report.episodes}
    assert [t.outcome for t in traces] == ["failure", "success"]
    for t in traces:
        e = episodes[t.seed]
        assert t.reproduced and "re-simulated alone on c" in t.resimulated
        assert t.steps == e.steps and len(t.frame["qpos"]) == len(t.reward) == e.steps + 1
        # Step 0 is the reset state; the rewards of steps 1..steps add up to the total.
        assert sequential_sum(t.reward[1:]) == np.float32(e.total_reward)


def test_trace_starts_at_the_seeds_reset_state(traces, push_c):
    for t in traces:
        state = jax.jit(push_c.reset)(seed_keys(jax.numpy.array([t.seed]))[0][0])
        np.testing.assert_array_equal(t.frame["qpos"][0], state.physics.quantities.qpos)
        # One env's reset, not the batch's fused arithmetic: equal to float32 ulps.
        np.testing.assert_allclose(t.frame["goal_xy"][0], state.info["goal_xy"], rtol=1e-6)


def test_choose_seeds_first_then_failures_without_repeats():
    arrays = {"success": np.array([True, False, True, False, False])}
    ev = Evaluation(None, None, None, None, np.arange(10, 15), arrays, None)
    assert choose_seeds(ev, 2, 2) == [10, 11, 13]
    assert choose_seeds(ev, 0, 5) == [11, 13, 14]
    assert choose_seeds(ev, 1) == [10]


def test_other_backends_rerun_the_evaluation_batch(scripted_eval, push_c, monkeypatch):
    """Where episodes depend on the batch layout, a seed is re-run inside its own chunk."""
    monkeypatch.setattr(push_c.backend, "layout_invariant", False)
    ev = dataclasses.replace(scripted_eval, timing=dataclasses.replace(scripted_eval.timing))
    [t] = trace_episodes(ev, [5])
    assert t.reproduced and "in its evaluation batch of 8" in t.resimulated


def _project(model, data, cam, point, width, height):
    """Pixel (column, row) of a world point in a MuJoCo camera (looks along -z, +y up)."""
    rot = data.cam_xmat[cam].reshape(3, 3)
    p = rot.T @ (np.asarray(point) - data.cam_xpos[cam])
    f = 0.5 * height / np.tan(np.deg2rad(model.cam_fovy[cam]) / 2)
    return round(width / 2 + f * p[0] / -p[2]), round(height / 2 - f * p[1] / -p[2])


def test_frames_show_the_recorded_state(traces, frames, scripted_eval):
    """The red cube is drawn where the recorded state puts it, projected through the camera
    independently of the renderer; the same state renders the same, another state not."""
    scene = scripted_eval.scene
    model = scene.mj_model
    data = mujoco.MjData(model)
    cam = model.camera("front").id
    cube = model.body("cube").id
    for t, video in zip(traces, frames, strict=True):
        data.qpos[:] = t.frame["qpos"][0]
        mujoco.mj_forward(model, data)
        col, row = _project(model, data, cam, data.xpos[cube], PANEL_W, PANEL_H)
        r, g, b = (
            video[0, HEADER_H + row - 1 : HEADER_H + row + 2, col - 1 : col + 2]
            .reshape(-1, 3)
            .mean(0)
        )
        assert r > 100 and r > 2 * g and r > 2 * b, (r, g, b)
    scene_panel = (slice(HEADER_H, None), slice(0, PANEL_W))
    a, b = frames[0][0][scene_panel], frames[1][0][scene_panel]
    assert (a != b).any(axis=-1).mean() > 0.001  # another seed: the cube and goal moved
    again = next(iter(episode_frames(scene, traces[0], "front", gl_module.gl_backend(), "")))
    np.testing.assert_array_equal(again[scene_panel], a)


def test_mp4_has_a_frame_per_step(traces, frames, scripted_eval, gl, tmp_path):
    t, composed = traces[0], frames[0]
    path = tmp_path / "episode.mp4"
    info = write_episode_video(path, scripted_eval.scene, "scripted", t, camera="front", gl=gl)
    assert (info.frames, info.height, info.width) == (t.steps + 1, HEADER_H + PANEL_H, 2 * PANEL_W)
    with av.open(str(path)) as f:
        stream = f.streams.video[0]
        decoded = [fr.to_ndarray(format="rgb24") for fr in f.decode(stream)]
        assert float(stream.average_rate) == pytest.approx(1 / scripted_eval.scene.control_dt)
        assert f"seed {t.seed}: failure at step {t.steps}" in f.metadata["title"]
        assert "same episode as evaluated" in f.metadata["comment"]
    assert len(decoded) == t.steps + 1 and decoded[0].shape == composed[0].shape
    # Lossy, but each decoded frame is its own step's: closest to it among first, middle, last.
    picks = [0, t.steps // 2, t.steps]
    for i in picks:
        err = [np.abs(decoded[i].astype(int) - composed[j]).mean() for j in picks]
        assert int(np.argmin(err)) == picks.index(i) and min(err) < 3, err
    assert not list(tmp_path.glob(".*.tmp"))


def test_policy_images_get_a_panel(traces, scripted_eval, gl):
    """A policy that observes an image gets a panel: depth in grey, near bright."""
    t = traces[1]
    depth = np.tile(np.linspace(0.5, 2.0, 32, dtype=np.float32), (t.steps + 1, 24, 1))
    t = dataclasses.replace(t, images={"depth": depth})
    frame = next(iter(episode_frames(scripted_eval.scene, t, "front", gl, "")))
    assert frame.shape[1] == 2 * PANEL_W + 448  # 32 x 24 scaled to the panel height
    row = frame[HEADER_H + PANEL_H // 2, PANEL_W : PANEL_W + 448, 0].astype(int)
    assert row[20] > row[-20] + 100  # near (left) bright, far (right) dark


def test_unknown_camera_and_missing_gl(scripted_eval, monkeypatch):
    with pytest.raises(ConfigError, match=r"unknown camera 'top'; valid: overhead, front"):
        gl_module.camera_id(scripted_eval.scene.mj_model, "top")
    monkeypatch.setattr(gl_module, "_candidates", lambda: ("no_such_backend",))
    gl_module.gl_backend.cache_clear()
    try:
        with pytest.raises(gl_module.GLUnavailable, match=r"no OpenGL backend.*libegl1"):
            gl_module.gl_backend()
    finally:
        gl_module.gl_backend.cache_clear()


def test_joint_plot_draws_targets_only_for_per_actuator_actions(traces, scripted_eval):
    """A joint plot draws each position servo's target from the action where the action is
    one control per actuator, and only the joints where it is not (an end-effector action,
    as LIBERO's 7-D OSC over 9 actuators, crashed the plot, 2026-12-02)."""
    from openral_mjx.viz.video import JointPlot

    scene, trace = scripted_eval.scene, traces[0]
    nu = scene.mj_model.nu
    wide = dataclasses.replace(trace, action=np.zeros((trace.steps + 1, nu + 2), np.float32))
    narrow = dataclasses.replace(trace, action=trace.action[:, : nu - 1])
    with_targets = JointPlot(scene, trace, 320, 200).image
    plain = JointPlot(scene, wide, 320, 200).image
    np.testing.assert_array_equal(JointPlot(scene, narrow, 320, 200).image, plain)  # no target
    assert plain.shape == with_targets.shape and (plain != with_targets).any()
