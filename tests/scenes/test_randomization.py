"""Per-env randomisation and sweeps (`scenes.factor_ranges`, `scenes.randomization`,
`evaluation.sweep`).

The physics factors are checked against MuJoCo C stepped by hand on a model copy holding the
env's values, read back from the env's state; the control and sensing factors against the
nominal scene fed the delayed or noiseless inputs by hand; the sweep against a known-sensitive
case (the push expert with a long action delay).
"""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import build_scene
from openral_mjx.evaluation.spec import RunSpec
from openral_mjx.evaluation.sweep import run_sweep
from openral_mjx.report.sweep import load_sweep, save_sweep
from openral_mjx.scenes.factor_ranges import FactorRange, grid_values, parse_factor, parse_factors
from openral_mjx.scenes.randomization import INFO_KEY, Randomized, randomize
from openral_mjx.stats import holm_adjusted

SEEDS = jnp.array([3, 11, 20])
FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS
PHYSICS = ("friction=0.1:1.0", "mass=0.5x:2x", "kp=0.5x:1.5x", "damping=0.5x:2x", "armature=2x:3x")


@pytest.fixture(scope="module")
def push():
    """tabletop_push on c (one thread: bit-identical to MuJoCo C stepped by hand)."""
    return build_scene("tabletop_push", backend="c", n_envs=4, threads=1)


# ---- parsing -------------------------------------------------------------------------------


def test_parse_forms():
    assert parse_factor("friction=0.3:1.2") == (FactorRange("friction", 0.3, 1.2), 1)
    assert parse_factor("mass=0.5x:2x") == (FactorRange("mass", 0.5, 2.0, True), 1)
    assert parse_factor("delay=2")[0].fixed
    assert parse_factor("delay=0:4:5", grid=True) == (FactorRange("delay", 0, 4), 5)
    assert grid_values(FactorRange("delay", 0, 3), 3) == [0.0, 2.0, 3.0]
    assert grid_values(FactorRange("friction", 0.2, 1.2), 6) == pytest.approx(
        [0.2, 0.4, 0.6, 0.8, 1.0, 1.2]
    )
    assert FactorRange("mass", 0.5, 2.0, True).label == "mass_scale"


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("fric=1", "unknown randomisation factor 'fric'; valid: friction, mass"),
        ("friction", "is not NAME=LOW:HIGH"),
        ("friction=a:1", "'a' is not a number"),
        ("friction=2:1", "low 2 is above high 1"),
        ("friction=-1:1", "friction must be >= 0"),
        ("mass=0:1", "mass must be > 0"),
        ("mass=0.5x:2", "write both ends as multiples"),
        ("delay=1x:2x", "delay takes absolute values only"),
        ("delay=0.5:2", "delay takes whole numbers"),
        ("delay=0:40", "delay must be >= 0 and <= 32"),
        ("depth_dropout=0:1.5", "depth_dropout must be >= 0 and <= 1"),
    ],
)
def test_bad_factor_is_a_config_error(item, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
        parse_factor(item)


def test_bad_sweep_and_repeats():
    with pytest.raises(ConfigError, match=r"N must lie in \[2, 1000\]"):
        parse_factor("friction=0.2:1:1", grid=True)
    with pytest.raises(ConfigError, match="not NAME=LOW:HIGH:N"):
        parse_factor("friction=0.2:1", grid=True)
    with pytest.raises(ConfigError, match="more than once"):
        parse_factors(["delay=0:1", "delay=2"])


def test_scene_without_a_target_refuses(push):
    with pytest.raises(ConfigError, match=r"cannot randomise 'depth_noise'.*valid: friction"):
        randomize(push, ["depth_noise=0:0.01"])


def test_light_needs_rendered_rgb_images(push):
    """Only RGB images see the lights, and only `warp` renders them: elsewhere `light` is a
    config error that says so."""
    assert parse_factor("light=0.5x:1.5x")[0] == FactorRange("light", 0.5, 1.5, True)
    with pytest.raises(ConfigError, match=r"cannot randomise 'light' \(.*rendered RGB images"):
        randomize(push, ["light=0.5x:1.5x"])
    depth = build_scene(
        "so101_box", {"obs_depth_cameras": ("overhead",)}, backend="c", n_envs=2, threads=1
    )
    with pytest.raises(ConfigError, match=r"cannot randomise 'light'.*valid: .*camera_rot"):
        randomize(depth, ["light=0.3:1"])


def test_holm_against_closed_form_and_simulation():
    # Sorted 0.005, 0.01, 0.03, 0.04 times 4, 3, 2, 1, then the running maximum.
    np.testing.assert_allclose(holm_adjusted([0.01, 0.04, 0.03, 0.005]), [0.03, 0.06, 0.06, 0.02])
    # Family-wise error under the global null (independent uniform p-values), by simulation:
    # at most alpha (Holm's bound is exact here: 1 - (1 - alpha/m)^m at the first step).
    rng = np.random.default_rng(0)
    p = rng.uniform(size=(20_000, 5))
    fwer = np.mean([(holm_adjusted(row) <= 0.05).any() for row in p])
    assert fwer == pytest.approx(1 - (1 - 0.05 / 5) ** 5, abs=0.006)
    assert fwer <= 0.05 + 0.006


# ---- physics factors: per-env model fields against MuJoCo C --------------------------------


def _reset(scene, seeds):
    keys = jax.vmap(lambda s: jax.random.split(jax.random.PRNGKey(s), 2)[0])(seeds)
    return jax.jit(jax.vmap(scene.reset_with_seed))(seeds, keys)


def test_physics_fields_per_env_match_mujoco_c(push):
    scene = randomize(push, PHYSICS)
    state = _reset(scene, SEEDS)
    nominal = _reset(push, SEEDS)
    # The initial state is the nominal run's: randomised runs pair with it seed by seed.
    np.testing.assert_array_equal(state.physics.quantities.qpos, nominal.physics.quantities.qpos)
    fields = {k: np.asarray(v) for k, v in state.physics.fields.items()}
    values = state.info[INFO_KEY]["values"]
    m = push.mj_model
    cube, table = m.geom("cube").id, m.geom("table").id
    np.testing.assert_allclose(fields["geom_friction"][:, cube, 0], values["friction"])
    np.testing.assert_allclose(fields["geom_friction"][:, table, 0], values["friction"])
    body = m.body("cube").id
    np.testing.assert_allclose(
        fields["body_mass"][:, body], m.body_mass[body] * values["mass"], rtol=1e-6
    )
    assert len(set(np.round(np.asarray(values["friction"]), 6))) == len(SEEDS)  # per env
    # The cube is a simple body: MuJoCo C reads its inertia from dof_M0, as mj_setConst sets it.
    for i in range(len(SEEDS)):
        mi = copy.copy(m)
        for name in ("body_mass", "body_inertia"):
            getattr(mi, name)[:] = fields[name][i]
        mujoco.mj_setConst(mi, mujoco.MjData(mi))
        dofs = np.flatnonzero(m.dof_bodyid == body)
        np.testing.assert_allclose(fields["dof_M0"][i, dofs], mi.dof_M0[dofs], rtol=1e-5)
    # Each env's trajectory is MuJoCo C's on a model copy holding that env's fields.
    rng = np.random.default_rng(1)
    low, high = (np.asarray(b) for b in push.action_bounds())
    actions = rng.uniform(low, high, size=(6, len(SEEDS), push.action_size)).astype(np.float32)
    step = jax.jit(jax.vmap(scene.step))
    s = state
    qpos = []
    for a in actions:
        s = step(s, jnp.asarray(a))
        qpos.append(np.asarray(s.physics.quantities.qpos))
    host = push.backend.host_model
    for i, seed_state in enumerate(np.asarray(nominal.physics.data)):
        model = copy.copy(host)
        for name, value in fields.items():
            getattr(model, name)[:] = value[i].astype(np.float64)
        d = mujoco.MjData(model)
        mujoco.mj_setState(model, d, np.asarray(seed_state).view(np.float64), FULL)
        for t, a in enumerate(actions):
            d.ctrl[:] = np.clip(a[i], low, high)
            mujoco.mj_step(model, d, nstep=push.backend.n_substeps)
            np.testing.assert_allclose(d.qpos, qpos[t][i], atol=2e-6)
    # ... and differs from the nominal model's.
    n = _reset(push, SEEDS)
    for a in actions:
        n = jax.jit(jax.vmap(push.step))(n, jnp.asarray(a))
    assert np.abs(np.asarray(n.physics.quantities.qpos) - qpos[-1]).max() > 1e-4


def test_factor_values_depend_on_the_seed_alone(push):
    scene = randomize(push, [*PHYSICS, "delay=0:4"])
    a = _reset(scene, SEEDS).info[INFO_KEY]["values"]
    b = _reset(scene, jnp.array([99, 20, 3, 11])).info[INFO_KEY]["values"]
    for k in a:
        np.testing.assert_array_equal(np.asarray(a[k]), np.asarray(b[k])[[2, 3, 1]])
    # Adding a factor leaves the others' draws alone.
    c = _reset(randomize(push, ["friction=0.1:1.0"]), SEEDS).info[INFO_KEY]["values"]
    np.testing.assert_array_equal(np.asarray(c["friction"]), np.asarray(a["friction"]))
    assert set(np.asarray(a["delay"]).tolist()) <= {0.0, 1.0, 2.0, 3.0, 4.0}


# ---- control and sensing factors against the nominal scene fed by hand ----------------------


def test_delay_executes_the_action_from_d_steps_before(push):
    d = 2
    scene = randomize(push, [f"delay={d}"])
    hold = scene.targets.hold
    s = _reset(scene, SEEDS)
    n = _reset(push, SEEDS)
    held = jax.vmap(hold)(n)
    rng = np.random.default_rng(2)
    low, high = (np.asarray(b) for b in push.action_bounds())
    actions = jnp.asarray(
        rng.uniform(low, high, size=(5, len(SEEDS), push.action_size)), jnp.float32
    )
    step_r, step_n = jax.jit(jax.vmap(scene.step)), jax.jit(jax.vmap(push.step))
    for t in range(len(actions)):
        s = step_r(s, actions[t])
        n = step_n(n, actions[t - d] if t >= d else held)
        np.testing.assert_array_equal(s.physics.quantities.qpos, n.physics.quantities.qpos)


def test_observation_noise_hits_only_its_slices(push):
    sigma = 0.02
    scene = randomize(push, [f"joint_noise={sigma}"])
    s = _reset(scene, jnp.arange(64))
    clean = np.asarray(s.info[INFO_KEY]["obs"])
    noise = np.asarray(s.obs) - clean
    start, size = push.obs_layout["joint_pos"]
    joint = noise[:, start : start + size]
    assert np.std(joint) == pytest.approx(sigma, rel=0.15)
    rest = np.delete(noise, np.arange(start, start + size), axis=1)
    np.testing.assert_array_equal(rest, 0.0)
    # The scene's own logic sees the true state: the physics is the nominal one.
    nominal = _reset(push, jnp.arange(64))
    np.testing.assert_array_equal(clean, nominal.obs)


def test_depth_noise_and_dropout():
    scene = build_scene(
        "tabletop_push",
        {"obs_depth_cameras": ("front",), "obs_depth_size": (16, 12)},
        backend="c",
        n_envs=4,
        threads=1,
    )
    r = randomize(scene, ["depth_noise=0.01", "depth_dropout=0.25"])
    assert isinstance(r, Randomized)
    key, top = r.targets.range_obs[0]
    start, size = scene.obs_layout[key]
    obs = jnp.zeros(scene.observation_size).at[start : start + size].set(0.5)
    obs = obs.at[start].set(top)  # a pixel with no return stays one
    values = {"depth_noise": jnp.float32(0.01), "depth_dropout": jnp.float32(0.25)}
    out = np.asarray(r._noisy_obs(obs, values, jax.random.PRNGKey(0)))[start : start + size]
    assert out[0] == top
    lost = out[1:] == top
    assert lost.mean() == pytest.approx(0.25, abs=0.1)
    assert np.std(out[1:][~lost] - 0.5) == pytest.approx(0.01, rel=0.3)


# ---- a known-sensitive case, through the sweep ------------------------------------------------


def test_sweep_delay_drops_the_push_expert(push, tmp_path):
    """The push expert steers by the cube's current pose: 12 control steps (0.6 s) of action
    delay ruin it, on the same 24 seeds that succeed without delay."""
    spec = RunSpec(n_envs=24, n_episodes=24, seed=0, batching="chunks")
    report = run_sweep(push, "scripted", "delay=0:12:2", spec)
    nominal, delayed = report.points
    assert nominal.success_rate >= 0.8
    assert delayed.success_rate <= nominal.success_rate - 0.4
    (step,) = report.steps
    assert step.significant and step.p_adjusted == step.p_value < 0.01
    path = tmp_path / "sweep.json"
    save_sweep(report, path)
    assert load_sweep(path) == report


def test_refill_gives_each_randomised_seed_its_chunked_episode(push):
    """Continuous batching resets slots to new seeds mid-run: each seed still gets its own
    factor values (per-env model copies rewritten for the reset rows only), so on `c` every
    episode is the fixed-chunk runner's, bit for bit."""
    from openral_mjx.policies import make_policy
    from openral_mjx.runner import run_seeds

    scene = randomize(push, ["friction=0.2:1.0", "mass=0.5x:2x", "delay=0:2", "joint_noise=0.002"])
    policy = make_policy("scripted", scene)
    seeds = np.arange(12)
    kw = {"seeds": seeds, "max_steps": 80}
    chunks, _ = run_seeds(scene, policy, None, n_envs=4, **kw)
    refill, _ = run_seeds(scene, policy, None, n_envs=4, batching="refill", **kw)
    assert 0 < chunks["success"].sum() < len(seeds)
    assert (chunks["steps"] < 80).any()  # slots do refill
    for k in chunks:
        np.testing.assert_array_equal(refill[k], chunks[k], err_msg=k)


def test_camera_jitter_moves_the_ray_cast_depth_camera():
    """`camera_pos`/`camera_rot` move each env's depth camera by the drawn distance and angle
    (read back from its fields), and its image is the one a camera built on a model copy with
    that pose casts (the ray caster itself is checked against `mj_multiRay`), from the reset
    on."""
    from openral_mjx import raycast

    options = {"obs_depth_cameras": ("front",), "obs_depth_size": (16, 12)}
    scene = build_scene("tabletop_push", options, backend="c", n_envs=4, threads=1)
    r = randomize(scene, ["camera_pos=0.02", "camera_rot=0.05"])
    seeds = SEEDS[:2]
    state, nominal = _reset(r, seeds), _reset(scene, seeds)
    m = scene.mj_model
    cam = m.camera("front").id
    pos = np.asarray(state.physics.fields["cam_pos"])[:, cam]
    quat = np.asarray(state.physics.fields["cam_quat"])[:, cam]
    np.testing.assert_allclose(np.linalg.norm(pos - m.cam_pos[cam], axis=1), 0.02, rtol=1e-4)
    turned = 2 * np.arccos(np.clip(np.abs(quat @ m.cam_quat[cam]), 0, 1))
    np.testing.assert_allclose(turned, 0.05, rtol=2e-2)
    key = "depth_front"
    start, size = scene.obs_layout[key]
    spec = scene.backend.ray_sensors[key].spec
    for i in range(len(seeds)):
        mi = copy.copy(scene.backend.host_model)
        mi.cam_pos[cam], mi.cam_quat[cam] = pos[i], quat[i]
        d = mujoco.MjData(mi)
        d.qpos[:] = np.asarray(state.physics.quantities.qpos[i])
        mujoco.mj_forward(mi, d)
        xpos, xquat = jnp.asarray(d.xpos, jnp.float32), jnp.asarray(d.xquat, jnp.float32)
        expected = np.asarray(raycast.depth_image(spec.build(mi), xpos, xquat)[0]).ravel()
        got = np.asarray(state.obs[i, start : start + size])
        np.testing.assert_allclose(got, expected, atol=1e-4)
        assert np.abs(got - np.asarray(nominal.obs[i, start : start + size])).max() > 1e-3


@pytest.mark.slow  # MuJoCo-Warp's renderer on the CPU: ~2 min of kernel builds
def test_camera_jitter_on_the_warp_renderer():
    """On warp, MuJoCo-Warp renders the images (depth and RGB) from each env's moved cameras:
    its depth equals the ray cast from the same pose, for a static camera and one on the
    moving wrist, at reset and after a step (the step places the cameras from the per-env
    model)."""
    pytest.importorskip("warp")
    from openral_mjx import raycast
    from openral_mjx.physics import PhysicsSettings
    from openral_mjx.physics.base import camera_local
    from openral_mjx.scenes import make_scene

    options = {
        "obs_depth_cameras": ["overhead", "wrist"],
        "obs_depth_size": [32, 24],
        "obs_rgb_cameras": ["overhead"],
        "obs_rgb_size": [32, 24],
    }
    scene = make_scene("so101_box", options, backend="warp", settings=PhysicsSettings(batch_size=2))
    r = randomize(scene, ["camera_pos=0.02", "camera_rot=0.05"])
    seeds = jnp.array([1, 2])
    state = _reset(r, seeds)
    action = np.random.default_rng(0).uniform(-0.6, 0.6, (2, scene.action_size))
    stepped = jax.jit(jax.vmap(r.step))(state, jnp.asarray(action, jnp.float32))
    nominal = _reset(scene, seeds)
    for s in (state, stepped):
        d, fields = s.physics.data, s.physics.fields
        for cam in ("overhead", "wrist"):
            spec = raycast.DepthSpec(cam, width=32, height=24, max_range_m=1.0)
            ours = spec.build(scene.mj_model)
            cid = scene.mj_model.camera(cam).id

            def cast(p, q, f, ours=ours, cid=cid):
                return raycast.depth_image(ours, p, q, camera_local(f, cid, scene.mj_model))[0]

            expected = jax.vmap(cast)(d.xpos, d.xquat, fields)
            rendered = s.physics.quantities.sensors[f"depth_{cam}"]
            np.testing.assert_allclose(np.asarray(rendered), np.asarray(expected), atol=1e-4)
    moved = np.asarray(state.physics.quantities.sensors["depth_overhead"])
    still = np.asarray(nominal.physics.quantities.sensors["depth_overhead"])
    assert np.abs(moved - still).max() > 1e-3


@pytest.mark.slow  # MuJoCo-Warp's renderer on the CPU: ~2 min of kernel builds
def test_light_on_the_warp_renderer():
    """On warp, each env's RGB image is lit by its own light: two envs' images differ, and
    each equals, bit for bit, the image of a backend built from a model whose light was set to
    that env's value by hand, at reset and after a step; a seed draws its value, and its
    image, in any batch."""
    pytest.importorskip("warp")
    from openral_mjx.physics import PhysicsSettings
    from openral_mjx.physics.warp_backend import WarpBackend
    from openral_mjx.scenes import make_scene

    options = {"obs_rgb_cameras": ["overhead"], "obs_rgb_size": [32, 24]}
    settings = PhysicsSettings(batch_size=2)
    scene = make_scene("so101_box", options, backend="warp", settings=settings)
    r = randomize(scene, ["light=0.2x:2x"])
    seeds = jnp.array([1, 2])
    state = _reset(r, seeds)
    action = np.random.default_rng(0).uniform(-0.6, 0.6, (2, scene.action_size))
    stepped = jax.jit(jax.vmap(r.step))(state, jnp.asarray(action, jnp.float32))
    m = scene.mj_model
    light = m.light("ceiling_light").id
    scale = np.asarray(state.info[INFO_KEY]["values"]["light"])
    np.testing.assert_array_equal(
        np.asarray(jax.vmap(r.episode_factors)(state)["light_scale"]), scale
    )
    diffuse = np.asarray(state.physics.fields["light_diffuse"])[:, light]
    np.testing.assert_allclose(diffuse, scale[:, None] * m.light_diffuse[light], rtol=1e-6)
    assert abs(scale[0] - scale[1]) > 0.2
    key = "rgb_overhead"
    start, size = scene.obs_layout[key]
    images = [np.asarray(s.physics.quantities.sensors[key]) for s in (state, stepped)]
    np.testing.assert_array_equal(
        np.asarray(state.obs[:, start : start + size]), images[0].reshape(2, -1)
    )
    for image in images:
        assert np.abs(image[0] - image[1]).max() > 0.1
    q = state.physics.quantities
    for i in range(2):
        spec = scene.spec.copy()
        spec.light("ceiling_light").diffuse = diffuse[i].tolist()
        by_hand = WarpBackend(spec, scene.backend.quantity_spec, scene.backend.n_substeps, settings)
        ref = jax.jit(jax.vmap(by_hand.init))(q.qpos[i : i + 1], q.qvel[i : i + 1])
        np.testing.assert_array_equal(np.asarray(ref.quantities.sensors[key])[0], images[0][i])
        render = jax.vmap(lambda d, c=by_hand.cameras: c.render(d)[0][key])
        ref = np.asarray(jax.jit(render)(stepped.physics.data))
        np.testing.assert_array_equal(ref[i], images[1][i])
    # The same seeds in the other order: the same values, the same images.
    again = _reset(r, seeds[::-1])
    np.testing.assert_array_equal(np.asarray(again.info[INFO_KEY]["values"]["light"]), scale[::-1])
    np.testing.assert_array_equal(
        np.asarray(again.physics.quantities.sensors[key]), images[0][::-1]
    )
