"""Depth cameras against MuJoCo's renderers: the pixel a ray goes through is the pixel the
renderer draws there (OpenGL, and MuJoCo-Warp's batch renderer in its CPU mode), with the
so101_box overhead camera's principal point moved off centre so that a sign error shows.
"""

from __future__ import annotations

import subprocess
import sys

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from openral_mjx import raycast
from openral_mjx.core.errors import ConfigError
from openral_mjx.physics import PhysicsSettings, warp_render
from openral_mjx.physics.warp_render import (
    _subtree_com,
    area_resampled,
    gl_material_terms,
    light_poses,
    render_model,
    srgb_to_linear,
    tracked_camera_pose,
    weighted_resampled,
)
from openral_mjx.scenes import So101BoxOptions, make_scene
from openral_mjx.scenes.so101_box import compose

# OAK-D-like intrinsics at 640 x 400 with the principal point 20 px left of and 20 px above
# the image centre.
OFF_CENTRE = {"overhead_camera_principal": [300.0, 180.0]}

_GL_RENDER = """
import sys
import mujoco
import numpy as np
xml, out, camera = sys.argv[1:4]
model = mujoco.MjModel.from_xml_path(xml)
data = mujoco.MjData(model)
data.qpos[:] = np.load(out + ".qpos.npy")
mujoco.mj_forward(model, data)
images = {}
for w, h in ((64, 40), (160, 100)):
    with mujoco.Renderer(model, h, w) as r:
        r.enable_depth_rendering()
        r.update_scene(data, camera)
        images[f"{w}x{h}"] = r.render()
np.savez(out, **images)
"""


def test_intrinsics_follow_the_options():
    """(cx, cy) options are where the optical axis crosses the image (pixel (u, v) covering
    [u, u + 1) x [v, v + 1)), at the camera's resolution and scaled to others."""
    model = compose(So101BoxOptions(overhead_camera_principal=(300.0, 180.0))).compile()
    cam = model.camera("overhead").id
    got = raycast.camera_intrinsics(model, cam, 640, 400)
    np.testing.assert_allclose(got, (383.0, 383.0, 300.0, 180.0), rtol=1e-5)
    np.testing.assert_allclose(
        raycast.camera_intrinsics(model, cam, 64, 40), (38.3, 38.3, 30.0, 18.0), rtol=1e-5
    )
    # 4:3 from a 16:10 sensor: the sensor's width is cropped, the height kept.
    fx, fy, cx, cy = raycast.camera_intrinsics(model, cam, 64, 48)
    assert fy == pytest.approx(383.0 * 48 / 400, rel=1e-5) and fx == pytest.approx(fy, rel=1e-5)
    assert cy == pytest.approx(24 - 20 * 48 / 400, rel=1e-5)
    assert cx == pytest.approx(32 - 20 * 48 / 400, rel=1e-5)


def test_ray_cast_depth_matches_mujocos_opengl_renderer(tmp_path):
    """MuJoCo's OpenGL renderer (headless EGL) draws the scene's depth where our rays go.

    Round geoms are tessellated there and depth comes from a z-buffer, so silhouettes and
    far surfaces differ a little: over 97% of pixels agree within 2 mm (measured: all of
    them). The principal point mirrored (the sign bug this guards against) moves the image by
    2 px and fails that. At the camera's aspect ratio only: for another one, OpenGL stretches
    the sensor over the image (non-square pixels) where MuJoCo-Warp, and so our cast, crops it.
    """
    spec = compose(So101BoxOptions(overhead_camera_principal=(300.0, 180.0)))
    model = spec.compile()
    xml = tmp_path / "scene.xml"
    xml.write_text(spec.to_xml())
    qpos = model.qpos0.copy()
    qpos[:6] = [0.3, -1.2, 0.9, 1.1, 0.4, 0.2]  # the arm reaching into view
    np.save(str(tmp_path / "out") + ".qpos.npy", qpos)
    proc = subprocess.run(
        [sys.executable, "-c", _GL_RENDER, str(xml), str(tmp_path / "out"), "overhead"],
        env={"MUJOCO_GL": "egl", "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    if proc.returncode != 0:
        pytest.skip(f"no headless OpenGL here: {proc.stderr.strip().splitlines()[-1:]}")
    rendered = np.load(tmp_path / "out.npz")
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    xpos, xquat = jnp.asarray(data.xpos, jnp.float32), jnp.asarray(data.xquat, jnp.float32)
    for w, h in ((64, 40), (160, 100)):
        gl = rendered[f"{w}x{h}"]
        ours = raycast.DepthSpec("overhead", width=w, height=h).build(model)
        depth = np.asarray(raycast.depth_image(ours, xpos, xquat)[0])
        assert np.mean(np.abs(depth - gl) < 2e-3) > 0.97, f"{w}x{h}"
        fx, fy, cx, cy = ours.intrinsics
        mirrored = raycast.DepthSpec(
            "overhead", width=w, height=h, intrinsics=(fx, fy, w - cx, h - cy)
        ).build(model)
        wrong = np.asarray(raycast.depth_image(mirrored, xpos, xquat)[0])
        assert np.mean(np.abs(wrong - gl) < 2e-3) < 0.9, f"{w}x{h} mirrored"


@pytest.fixture(scope="module")
def box_warp_cameras():
    """so101_box on warp (CPU mode) with two depth cameras and an RGB one, off-centre."""
    options = {
        **OFF_CENTRE,
        "obs_depth_cameras": ["overhead", "wrist"],
        "obs_depth_size": [32, 24],
        "obs_rgb_cameras": ["overhead"],
        "obs_rgb_size": [32, 24],
    }
    return make_scene("so101_box", options, backend="warp", settings=PhysicsSettings(batch_size=3))


@pytest.fixture(scope="module")
def warp_states(box_warp_cameras):
    scene = box_warp_cameras
    keys = jax.vmap(jax.random.PRNGKey)(jnp.arange(3))
    state = jax.jit(jax.vmap(scene.reset))(keys)
    action = np.random.default_rng(0).uniform(-0.6, 0.6, (3, scene.action_size))
    return state, jax.jit(jax.vmap(scene.step))(state, jnp.asarray(action, jnp.float32))


@pytest.mark.heavy
def test_warp_renderer_depth_matches_the_ray_cast_on_the_same_state(box_warp_cameras, warp_states):
    """On warp the depth observation is MuJoCo-Warp's render; on the same state (its body
    poses) the ray cast draws the same image: measured within 7.5e-6 m on every pixel of
    both scenes' cameras (bound 1e-4 m)."""
    scene = box_warp_cameras
    assert scene.backend.rendered == {"depth_overhead", "depth_wrist", "rgb_overhead"}
    for state in warp_states:
        d = state.physics.data
        for cam in ("overhead", "wrist"):
            ours = raycast.DepthSpec(cam, width=32, height=24, max_range_m=1.0).build(
                scene.mj_model
            )
            cast = jax.vmap(lambda p, q, c=ours: raycast.depth_image(c, p, q)[0])(d.xpos, d.xquat)
            rendered = state.physics.quantities.sensors[f"depth_{cam}"]
            assert rendered.shape == (3, 24, 32)
            np.testing.assert_allclose(np.asarray(rendered), np.asarray(cast), atol=1e-4)
            assert float(jnp.min(rendered)) < 0.5  # not an empty image: the floor, objects


def test_sensor_slices_of_the_observation(box_warp_cameras, warp_states):
    scene = box_warp_cameras
    _, state = warp_states
    q = state.physics.quantities
    layout, shapes = scene.obs_layout, scene.obs_shapes
    assert shapes["depth_overhead"] == (24, 32) and shapes["rgb_overhead"] == (24, 32, 3)
    assert scene.observation_size == sum(size for _, size in layout.values())
    for key in ("depth_overhead", "depth_wrist", "rgb_overhead"):
        start, size = layout[key]
        got = state.obs[:, start : start + size].reshape(-1, *shapes[key])
        np.testing.assert_array_equal(got, q.sensors[key])
    rgb = np.asarray(q.sensors["rgb_overhead"])
    assert rgb.min() >= 0 and rgb.max() <= 1 and rgb.std() > 0.01


def test_warp_draws_only_the_steps_asked_and_the_poses_before_their_last(
    box_warp_cameras, warp_states, monkeypatch
):
    """A step with ``render=False`` draws nothing and keeps the previous images (the LIBERO
    mirror draws 1 of its 25 physics steps), with the physics unchanged. A step that renders
    draws its data's poses, which `mjx.step` computes before integrating, as `mj_step` does:
    those of the state one physics step earlier (where LIBERO's images come from), not of
    the state the step ends in (what `c` draws)."""
    backend = box_warp_cameras.backend
    monkeypatch.setattr(backend, "n_substeps", 1)  # read when a step is traced
    start = warp_states[1].physics
    ctrl = jnp.asarray(
        np.random.default_rng(1).uniform(-0.5, 0.5, (3, backend.mj_model.nu)), jnp.float32
    )
    step = jax.jit(jax.vmap(backend.step))
    skip = jax.jit(jax.vmap(lambda s, c: backend.step(s, c, render=False)))(start, ctrl)
    one = step(start, ctrl)
    np.testing.assert_array_equal(skip.quantities.qpos, one.quantities.qpos)
    for key in backend.rendered:
        np.testing.assert_array_equal(skip.quantities.sensors[key], start.quantities.sensors[key])
    two = step(one, ctrl)
    init = jax.jit(jax.vmap(backend.init))
    before, after = (init(s.quantities.qpos, s.quantities.qvel) for s in (one, two))
    # the poses drawn after step two are those of the state step one ended in
    np.testing.assert_allclose(two.data.geom_xpos, before.data.geom_xpos, atol=1e-5)
    assert np.abs(two.data.geom_xpos - after.data.geom_xpos).max() > 1e-4
    for key in backend.rendered:  # a step's camera and lights are `mj_camlight`'s, init's ours
        got, want = two.quantities.sensors[key], before.quantities.sensors[key]
        # measured: all but 2 of the 6,912 RGB values within 2e-3 (an edge pixel's, by 16/255)
        assert np.mean(np.abs(got - want) <= 1e-3) >= 0.99, key
        assert not np.array_equal(got, one.quantities.sensors[key]), key  # drawn anew


_TEXTURES = """
<mujoco>
  <asset>
    <texture name="srgb" type="2d" builtin="flat" rgb1="0.5 0.5 0.5" width="4" height="4"
             colorspace="sRGB"/>
    <texture name="linear" type="2d" builtin="flat" rgb1="0.5 0.5 0.5" width="4" height="4"
             colorspace="linear"/>
  </asset>
  <worldbody/>
</mujoco>
"""


def test_warp_draws_srgb_textures_decoded_as_mujocos_renderer_does():
    """MuJoCo's renderer samples an sRGB texture's texels decoded to linear values; the model
    MuJoCo-Warp draws holds them decoded (127 -> 54), the others and the physics' model as
    they were. LIBERO's floor is such a texture: undecoded, warp drew it ~30/255 brighter."""
    model = mujoco.MjModel.from_xml_string(_TEXTURES)
    drawn = render_model(model)
    srgb, linear = (drawn.tex(n).id for n in ("srgb", "linear"))
    texels = lambda m, t: m.tex_data[m.tex_adr[t] : m.tex_adr[t] + 48]  # noqa: E731
    assert set(texels(model, srgb)) == {127} and set(texels(drawn, srgb)) == {54}
    np.testing.assert_array_equal(texels(drawn, linear), texels(model, linear))
    assert drawn.tex_colorspace[srgb] == mujoco.mjtColorSpace.mjCOLORSPACE_LINEAR
    assert model.tex_colorspace[srgb] == mujoco.mjtColorSpace.mjCOLORSPACE_SRGB
    plain = mujoco.MjModel.from_xml_string(_TEXTURES.replace('"sRGB"', '"linear"'))
    assert render_model(plain) is plain
    assert srgb_to_linear(np.array([0, 10, 255], np.uint8)).tolist() == [0, 1, 255]


# A LIBERO-like table: a textured top with specular 0.2 and shininess 0, a spot light above
# it and MuJoCo's headlight; the light's diffuse kept low enough that OpenGL's lit colour stays
# under 1 (it clamps that sum before the texture modulates it; MuJoCo-Warp does not).
_SPECULAR_TABLE = """
<mujoco>
  <visual><headlight ambient="0.1 0.1 0.1" diffuse="0.4 0.4 0.4" specular="0.5 0.5 0.5"/></visual>
  <asset>
    <texture name="wood" type="2d" builtin="checker" rgb1="0.8 0.6 0.4" rgb2="0.6 0.5 0.3"
             width="8" height="8" colorspace="linear"/>
    <material name="top" texture="wood" specular="0.2" shininess="0"/>
    <material name="shiny" texture="wood" specular="0.5" shininess="0.5"/>
    <material name="plain" rgba="0.5 0.5 0.5 1" specular="0.3" shininess="0"/>
  </asset>
  <worldbody>
    <light pos="1 1 4" dir="0 -0.148 -0.989" cutoff="45" exponent="10" specular="0.3 0.3 0.3"
           diffuse="0.5 0.5 0.5"/>
    <camera name="view" pos="0 -1.2 1.6" xyaxes="1 0 0 0 0.8 0.6"/>
    <geom name="table" type="box" size="0.5 0.6 0.025" pos="0 0 0.8" material="top"/>
    <geom type="sphere" size="0.01" pos="0 0 -5" material="shiny"/>
    <geom type="sphere" size="0.01" pos="0 1 -5" material="plain"/>
  </worldbody>
</mujoco>
"""


def test_gl_specular_of_textured_materials_as_warp_draws_it():
    """At shininess 0 OpenGL's specular is specular x light x spot factor x texture (no view
    dependence): emission to MuJoCo-Warp. Shinier textured materials keep their highlight,
    scaled by the texture's mean; untextured ones are untouched."""
    model = mujoco.MjModel.from_xml_string(_SPECULAR_TABLE)
    emission, specular = gl_material_terms(model)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    to_table = data.geom_xpos[model.geom("table").id] - data.light_xpos[0]
    cos = np.dot(to_table, data.light_xdir[0]) / np.linalg.norm(to_table)
    assert cos > np.cos(np.deg2rad(45))  # inside the cone
    top, shiny, plain = (model.mat(n).id for n in ("top", "shiny", "plain"))
    assert emission[top] == pytest.approx(0.2 * (0.5 + 0.3 * cos**10), rel=1e-5)
    assert specular[top] == pytest.approx(0.2)  # MuJoCo-Warp skips it at shininess 0
    mean = np.mean([0.8, 0.6, 0.4, 0.6, 0.5, 0.3])  # the checker's two colours, equal shares
    assert specular[shiny] == pytest.approx(0.5 * mean, abs=2e-3) and emission[shiny] == 0
    assert (emission[plain], specular[plain]) == (0, pytest.approx(0.3))


def _warp_table(samples: int = 1) -> np.ndarray:
    """`_SPECULAR_TABLE`'s camera on `warp` (CPU), 32 x 24, textures on, in 1/255."""
    from openral_mjx.physics import QuantitySpec, make_backend
    from openral_mjx.physics.cameras import RgbSpec, RgbStyle

    spec = mujoco.MjSpec.from_string(_SPECULAR_TABLE)
    style = RgbStyle(textures=True, samples=samples)
    rgb = RgbSpec("view", 32, 24, style=style)
    backend = make_backend("warp", spec, QuantitySpec(sensors=(rgb,)), 1)
    state = jax.jit(jax.vmap(backend.init))(jnp.zeros((1, 0)), jnp.zeros((1, 0)))
    return np.round(np.asarray(state.quantities.sensors["rgb_view"][0]) * 255)


def _gl_table(gl: str) -> np.ndarray:
    """The same camera drawn by MuJoCo's OpenGL renderer (4 samples per pixel)."""
    from openral_mjx.physics.gl import FrameRenderer

    model = mujoco.MjModel.from_xml_string(_SPECULAR_TABLE)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with FrameRenderer(model, 32, 24, gl) as r:
        return r.render(data, model.camera("view").id).astype(np.float64)


@pytest.mark.heavy  # Warp's CPU kernels for a box scene (~1 min cold)
def test_warp_lights_a_shininess_zero_texture_as_mujocos_renderer_does(gl: str):
    """LIBERO's tables (specular 0.2, shininess 0) came out ~22/255 darker on warp than in
    MuJoCo's renderer: 47% of agentview pixels within 8/255 on `libero_spatial/0`, 90% with
    the specular drawn as emission. Here the table's top, inside its edges, against MuJoCo's
    OpenGL renderer: measured 0.8/255 apart on average (every pixel within 8/255) with it,
    17.6/255 darker without."""
    want = _gl_table(gl)
    inner = (slice(1, 10), slice(8, 24))  # the top, away from its edges
    diff = (_warp_table() - want)[inner]
    assert np.abs(diff).mean() <= 3 and np.mean(np.abs(diff).max(-1) <= 8) >= 0.95, diff
    with pytest.MonkeyPatch.context() as mp:  # without: the top's specular is lost
        mp.setattr(warp_render, "gl_material_terms", lambda m: (m.mat_emission, m.mat_specular))
        assert (_warp_table() - want)[inner].mean() < -12


@pytest.mark.heavy
def test_two_samples_per_axis_draw_edges_as_mujocos_multisampled_renderer(gl: str):
    """`RgbStyle.samples` (libero_mjx's `image_samples`): the whole image, edges included,
    against MuJoCo's renderer (4 samples per pixel). Measured: one sample 4.7/255 apart on
    average, 87.9% of pixels within 8/255; two per axis 1.6/255 and 96.0%."""
    want = _gl_table(gl)
    one, two = (np.abs(_warp_table(n) - want).max(-1) for n in (1, 2))
    assert two.mean() < 0.5 * one.mean() and np.mean(two <= 8) >= 0.95 > np.mean(one <= 8)


_CHECKERS = """
<mujoco>
  <asset>
    <texture name="board" type="2d" builtin="checker" rgb1="1 1 1" rgb2="0 0 0" width="64"
             height="64" colorspace="linear"/>
    <texture name="cube" type="cube" builtin="checker" rgb1="1 1 1" rgb2="0 0 0" width="32"
             height="32" colorspace="linear"/>
    <texture name="small" type="2d" builtin="checker" rgb1="1 1 1" rgb2="0 0 0" width="8"
             height="8" colorspace="linear"/>
  </asset>
  <worldbody/>
</mujoco>
"""


def test_area_resampling_weights_each_texel_by_the_area_it_covers():
    """Three texels 0, 30, 60 in two: each new texel covers one and a half old ones, so
    (0 + 30 / 2) / 1.5 = 10 and (30 / 2 + 60) / 1.5 = 50; along the other axis, kept."""
    ramp = np.array([0, 30, 60], np.uint8).reshape(1, 3, 1).repeat(2, axis=0)
    np.testing.assert_array_equal(area_resampled(ramp, 2, 2)[..., 0], [[10, 50], [10, 50]])


@pytest.mark.parametrize("shape", [(4096, 4096, 64, 64, 3), (256, 512, 2, 8, 4), (64, 64, 1, 1, 3)])
def test_power_of_two_blocks_average_as_the_weights_do(shape):
    """Blocks of 2^n texels are averaged by their sums: the same texels as the general
    weights give, on random texels and on ones whose means end in exact halves (0 and 255:
    rounded to even); a 2 x 2 block of 0, 255, 255, 0 is 127.5, so 128."""
    h, w, height, width, c = shape
    rng = np.random.default_rng(0)
    for texels in (rng.integers(0, 256, (h, w, c)), rng.integers(0, 2, (h, w, c)) * 255):
        texels = texels.astype(np.uint8)
        np.testing.assert_array_equal(
            area_resampled(texels, height, width), weighted_resampled(texels, height, width)
        )
    block = np.array([[0, 255], [255, 0]], np.uint8)[..., None]
    assert area_resampled(block, 1, 1).item() == 128


def test_prefilter_replaces_each_wide_texture_by_its_mipmap_level():
    """`texels`: a texture wider than that is replaced by the mipmap level that wide, which
    MuJoCo's renderer would sample it from (a cube's faces each alone). MuJoCo's checker
    builtin is 2 x 2 squares of half the texture's side. At 1 texel a texture is one texel
    of its mean, a cube one per face; at 16 the 64-wide board's 32-texel squares are 8 wide;
    at 25 a level texel straddles the squares' edge and mixes them; a texture no wider than
    `texels`, and the physics' model, keep their texels."""
    model = mujoco.MjModel.from_xml_string(_CHECKERS)

    def image(m, name):
        t = m.tex(name).id
        w, h, c = m.tex_width[t], m.tex_height[t], m.tex_nchannel[t]
        return m.tex_data[m.tex_adr[t] : m.tex_adr[t] + w * h * c].reshape(h, w, c).astype(float)

    board, cube = image(model, "board"), image(model, "cube")
    assert set(np.unique(board)) == {0.0, 255.0}  # a checker of white and black
    flat = render_model(model, texels=1)
    assert image(flat, "board").shape == (1, 1, 3)
    assert np.abs(image(flat, "board") - 127.5).max() <= 0.5
    w = cube.shape[1]
    faces = [cube[f * w : (f + 1) * w].mean(axis=(0, 1)) for f in range(cube.shape[0] // w)]
    np.testing.assert_allclose(image(flat, "cube")[:, 0], faces, atol=0.5)
    level = image(render_model(model, texels=16), "board")
    np.testing.assert_array_equal(level, board[::4, ::4])  # 4 x 4 blocks inside one square
    mixed = image(render_model(model, texels=25), "board")
    assert mixed.shape == (25, 25, 3) and abs(mixed.mean() - board.mean()) <= 1.0
    assert abs(mixed[12, 0, 0] - 127.5) <= 0.5 and mixed[0, 0, 0] in (0, 255)  # the edge: 12.5
    assert np.abs(image(flat, "small") - 127.5).max() <= 0.5  # 8 wide: filtered at 1
    np.testing.assert_array_equal(
        image(render_model(model, texels=8), "small"), image(model, "small")
    )
    assert render_model(model, texels=64) is model  # nothing wider, nothing sRGB
    np.testing.assert_array_equal(image(model, "board"), board)  # the physics' model as it was


def test_rgb_needs_a_renderer():
    with pytest.raises(ConfigError, match="rgb camera 'rgb_overhead' needs backend warp or c"):
        make_scene("so101_box", {"obs_rgb_cameras": ["overhead"]}, backend="mjx")


_LIGHTS = """
<mujoco>
  <worldbody>
    <light name="world" pos="0.2 0 2" dir="0 0.3 -1"/>
    <body name="arm" pos="0 0 1">
      <joint type="hinge" axis="0 1 0"/>
      <geom type="capsule" size="0.05" fromto="0 0 0 0.5 0 0" mass="1"/>
      <light name="fixed" pos="0.3 0 0.1" dir="1 0 -1" mode="fixed"/>
      <light name="track" pos="0 0.2 0.3" dir="0 0 -1" mode="track"/>
      <light name="trackcom" pos="0 0.1 0.5" dir="0 1 -1" mode="trackcom"/>
      <body name="hand" pos="0.5 0 0">
        <joint type="ball"/>
        <geom type="box" size="0.1 0.05 0.05" pos="0.2 0 0" mass="2"/>
        <light name="target" pos="0 0 0.4" mode="targetbody" target="arm"/>
        <light name="targetcom" pos="0.1 0 0.4" mode="targetbodycom" target="arm"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_light_poses_match_mujoco():
    """The warp backend places the lights for the reset's images (kinematics leaves them
    unset): where `mj_forward` puts them, in every light mode, on static and moving bodies
    (measured: within 3e-7)."""
    model = mujoco.MjModel.from_xml_string(_LIGHTS)
    assert set(model.light_mode.tolist()) == set(range(5))  # fixed, track, trackcom, targets
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    for _ in range(3):
        data.qpos[0] = rng.uniform(-1, 1)
        quat = rng.normal(size=4)
        data.qpos[1:5] = quat / np.linalg.norm(quat)
        mujoco.mj_forward(model, data)
        xpos, xquat, xipos = (
            jnp.asarray(a, jnp.float32) for a in (data.xpos, data.xquat, data.xipos)
        )
        pos, direction = light_poses(model, xpos, xquat, xipos)
        np.testing.assert_allclose(np.asarray(pos), data.light_xpos, atol=1e-6)
        np.testing.assert_allclose(np.asarray(direction), data.light_xdir, atol=1e-6)


_TRACKING = """
<mujoco>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint type="hinge" axis="0 1 0"/>
      <geom type="capsule" size="0.05" fromto="0 0 0 0.5 0 0" mass="1"/>
      <body name="hand" pos="0.5 0 0">
        <joint type="ball"/>
        <geom type="box" size="0.1 0.05 0.05" pos="0.2 0 0" mass="2"/>
        <camera name="track" pos="-0.2 0.1 0.3" xyaxes="0 -1 0 1 0 1" mode="track"/>
        <camera name="trackcom" pos="0.1 0.2 0.4" xyaxes="1 0 0 0 1 1" mode="trackcom"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_tracking_camera_poses_match_mujoco():
    """MetaWorld's `behindGripper` and `gripperPOV` track the hand: the warp backend places
    `track` and `trackcom` cameras where `mj_forward` does (measured: within 4e-8)."""
    model = mujoco.MjModel.from_xml_string(_TRACKING)
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    for _ in range(3):
        data.qpos[0] = rng.uniform(-1, 1)
        quat = rng.normal(size=4)
        data.qpos[1:5] = quat / np.linalg.norm(quat)
        mujoco.mj_forward(model, data)
        xpos, xipos = jnp.asarray(data.xpos, jnp.float32), jnp.asarray(data.xipos, jnp.float32)
        com = _subtree_com(model, xipos)
        for cam in range(model.ncam):
            pos, rot = tracked_camera_pose(model, cam, xpos, com)
            np.testing.assert_allclose(np.asarray(pos), data.cam_xpos[cam], atol=1e-6)
            np.testing.assert_allclose(np.asarray(rot), data.cam_xmat[cam].reshape(3, 3), atol=1e-6)
