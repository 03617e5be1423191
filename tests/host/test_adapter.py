"""The host adapter on `point_reach` (worker processes of this interpreter): episodes against
the same env stepped directly in a Python loop, determinism, faults and clean-up."""

import dataclasses
import os
import signal
import subprocess
import sys
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import evaluate
from openral_mjx.evaluation.suite import merge_reports
from openral_mjx.host.batch import BatchConfig, EnvBatch
from openral_mjx.host.point_reach import IMAGE, TARGETS, PointReachEnv
from openral_mjx.host.pool import RemoteError, Worker
from openral_mjx.policies import make_policy
from openral_mjx.policies.mlp import MlpConfig, init_params, mlp_policy
from openral_mjx.runner import EpisodeRunner, compile_cache, export_cache, run_seeds
from openral_mjx.scenes import make_scene
from openral_mjx.scenes.host_scene import HostScene
from openral_mjx.stats import wilson_interval

STEPS = 12


@pytest.fixture(scope="module")
def reach():
    scene = make_scene("point_reach", {"n_workers": 2, "max_steps": STEPS})
    yield scene
    scene.close()


def _run(scene, seeds, n_envs, record=False):
    pol = make_policy("random", scene)
    return run_seeds(
        scene,
        pol,
        None,
        seeds=np.asarray(seeds),
        n_envs=n_envs,
        max_steps=STEPS,
        record=("actions",) if record else (),
    )[0]


def test_episodes_match_the_env_stepped_directly(reach):
    """Each seed replayed in-process with the actions the runner took: same rewards, steps,
    success, first success; seed s starts from target s mod 8 and the env's reset seed is
    drawn from the episode's reset key."""
    seeds = np.arange(6)
    out = _run(reach, seeds, 6, record=True)
    reset_keys = jax.vmap(lambda s: jax.random.split(jax.random.PRNGKey(s))[0])(jnp.arange(6))
    env_seeds = jax.vmap(lambda k: jax.random.randint(k, (), 0, 2**31 - 1, dtype=jnp.int32))(
        reset_keys
    )
    for i, seed in enumerate(seeds):
        env = PointReachEnv()
        env.reset(seed=int(env_seeds[i]), options={"init_state": int(seed) % len(TARGETS)})
        total, steps, first = np.float32(0), 0, -1
        for t in range(STEPS):
            _, reward, terminated, _, info = env.step(out["actions"][i, t])
            total = np.float32(total + np.float32(reward))
            steps += 1
            if info["is_success"]:
                first = t + 1
            if terminated:
                break
        assert out["total_reward"][i] == total and out["steps"][i] == steps
        assert out["first_success_step"][i] == first and out["success"][i] == (first > 0)


def test_same_seed_same_episode_at_any_batch_size_and_worker_count(reach):
    seeds = np.arange(7)
    whole = _run(reach, seeds, 7)
    chunked = _run(reach, seeds, 3)  # 3 + 3 + 1 (padded): workers reset for every chunk
    one_worker = make_scene("point_reach", {"n_workers": 1, "max_steps": STEPS})
    try:
        single = _run(one_worker, seeds, 7)
    finally:
        one_worker.close()
    for other in (chunked, single):
        for key in ("success", "steps", "total_reward", "first_success_step", "info/error"):
            np.testing.assert_array_equal(whole[key], other[key], err_msg=key)


def test_a_vector_drawn_from_the_reset_key_reaches_the_envs_reset(reach):
    """`HostSceneSpec.reset_draw` (how a host scene starts seed s where its mirror does): the
    vector drawn from seed s's reset key is the env's reset option, at any batch size."""
    draw = lambda key: jax.random.uniform(key, (2,), minval=0.1, maxval=0.9)  # noqa: E731
    spec = dataclasses.replace(
        reach.host_spec, reset_draw=draw, reset_draw_option="target", n_init_states=0
    )
    scene = HostScene(spec, reach.options, reach.env_name, reach.batch.config.python)
    seeds = jnp.arange(5, dtype=jnp.int32)
    keys = jax.vmap(lambda s: jax.random.split(jax.random.PRNGKey(s))[0])(seeds)
    try:
        state = jax.vmap(scene.reset_with_seed)(seeds, keys)
        one = jax.vmap(scene.reset_with_seed)(seeds[3:4], keys[3:4])
    finally:
        scene.close()
    np.testing.assert_array_equal(state.obs["state"][:, 2:], jax.vmap(draw)(keys))
    np.testing.assert_array_equal(one.obs["state"][0], state.obs["state"][3])


def test_a_flat_observation_is_its_entries_concatenated(reach):
    """`HostSceneSpec.flat_obs` (a host scene without cameras, as a mirror without them): one
    float32 vector, the declared entries in order, laid out by `obs_layout`; an MLP, which
    needs a flat vector, runs on it and acts on the env's state."""
    batch = dataclasses.replace(reach.host_spec.batch, observation={"state": ((4,), "float32")})
    spec = dataclasses.replace(reach.host_spec, batch=batch, flat_obs=True)
    flat = HostScene(spec, reach.options, reach.env_name, reach.batch.config.python)
    seeds = jnp.arange(3, dtype=jnp.int32)
    keys = jax.vmap(lambda s: jax.random.split(jax.random.PRNGKey(s))[0])(seeds)
    config = MlpConfig(obs_size=4, action_size=2, action_offset=(0.0,) * 2, action_scale=(1.0,) * 2)
    try:
        got = jax.vmap(flat.reset_with_seed)(seeds, keys)
        want = jax.vmap(reach.reset_with_seed)(seeds, keys)
        params = init_params(config, jax.random.PRNGKey(0))
        policy = mlp_policy(config)
        out = run_seeds(
            flat,
            policy,
            params,
            seeds=np.arange(3),
            n_envs=3,
            max_steps=STEPS,
            record=("actions",),
        )[0]
    finally:
        flat.close()
    assert flat.obs_layout == {"state": (0, 4)} and flat.observation_size == 4
    assert got.obs.dtype == jnp.float32
    np.testing.assert_array_equal(got.obs, want.obs["state"])
    assert (out["steps"] > 0).all() and (out["info/error"] == 0).all()
    first = jax.vmap(lambda o: policy.act(params, None, o, keys[0])[0])(got.obs)
    np.testing.assert_allclose(out["actions"][:, 0], first, rtol=1e-6)  # from the state
    with pytest.raises(ValueError, match="1-D"):
        dataclasses.replace(reach.host_spec, flat_obs=True)  # its image is not a vector


def test_a_dict_observation_is_no_flat_vector(reach):
    with pytest.raises(ConfigError, match="not one flat vector"):
        _ = reach.observation_size
    assert reach.obs_layout == {}


def test_finished_envs_are_not_stepped():
    config = BatchConfig(
        python=sys.executable,
        factory="openral_mjx.host.point_reach:make",
        kwargs={},
        observation={"state": ((4,), "float32"), "image": ((IMAGE, IMAGE, 3), "uint8")},
        action_size=2,
        n_workers=2,
    )
    batch = EnvBatch(config)
    try:
        first = batch.reset(np.array([5, 6]), [{"init_state": 0}, {"init_state": 1}])
        out = batch.step(np.ones((2, 2), np.float32), np.array([True, False]))
        np.testing.assert_array_equal(out["obs"]["state"][0], first["obs"]["state"][0])
        assert out["reward"][0] == 0.0
        assert not np.array_equal(out["obs"]["state"][1], first["obs"]["state"][1])
        again = batch.step(np.ones((2, 2), np.float32), np.array([False, False]))
        np.testing.assert_array_equal(again["obs"]["state"][0], first["obs"]["state"][0])
    finally:
        batch.close()


def _faulty(fault, **extra):
    options = {
        "n_workers": 2,
        "max_steps": STEPS,
        "fault": fault,
        "fault_init_state": 1,
        "fault_step": 2,
        **extra,
    }
    return evaluate("point_reach", "random", n_envs=4, n_episodes=8, options=options)


@pytest.fixture(scope="module")
def clean_run():
    return evaluate("point_reach", "random", n_envs=4, n_episodes=8, options={"max_steps": STEPS})


@pytest.mark.parametrize(
    "fault,extra,failed,needle",
    [
        ("crash", {}, {0, 1}, "worker 0 exited (exit code 3)"),
        ("hang", {"step_timeout_s": 2.0}, {0, 1}, "worker 0 did not answer within 2 s"),
        ("raise", {}, {1}, "env 1: RuntimeError: injected fault at step 2"),
    ],
)
def test_a_fault_fails_only_its_own_episodes(clean_run, fault, extra, failed, needle):
    """Seed 1 (init state 1) faults at its third step. A crash or hang takes down worker 0,
    which holds envs 0 and 1; an exception fails env 1 alone. The rest of the batch, and the
    next chunk (seeds 4..7, on a restarted worker), match a run without the fault."""
    report = _faulty(fault, **extra)
    assert report.n_episodes == 8
    for ep, ref in zip(report.episodes, clean_run.episodes, strict=True):
        seed = ep.metadata["seed"]
        if seed in failed:
            assert not ep.success and needle in ep.metadata["error"], ep.metadata["error"]
            assert ep.steps == 3
        else:
            assert ep.metadata["error"] is None
            assert (ep.success, ep.steps, ep.total_reward) == (
                ref.success,
                ref.steps,
                ref.total_reward,
            )


def test_a_diverged_env_ends_its_episode_as_diverged(clean_run):
    """An env whose step reports `info["diverged"]` (its physics blew up) ends that episode as
    a diverged failure, with no error; the other episodes match a run without it."""
    report = _faulty("diverge")
    assert report.diverged == 1
    for ep, ref in zip(report.episodes, clean_run.episodes, strict=True):
        assert ep.metadata["error"] is None
        if ep.metadata["seed"] == 1:
            assert ep.metadata["diverged"] and not ep.success and ep.steps == 3
        else:
            assert not ep.metadata["diverged"]
            assert (ep.success, ep.steps, ep.total_reward) == (
                ref.success,
                ref.steps,
                ref.total_reward,
            )


def _workers_of(marker: str) -> list[int]:
    """Processes whose environment carries `marker` (the workers of one test run)."""
    found = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        try:
            with open(f"/proc/{pid}/environ", "rb") as f:
                env = f.read()
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read()
        except OSError:
            continue
        if marker.encode() in env and b"openral_mjx.host.worker" in cmd:
            found.append(int(pid))
    return found


@pytest.mark.parametrize(
    "stop, code",
    [
        pytest.param(signal.SIGINT, 130, id="SIGINT"),
        pytest.param(signal.SIGTERM, 143, id="SIGTERM", marks=pytest.mark.heavy),  # ~20 s more
    ],
)
def test_ctrl_c_ends_the_run_and_its_workers(tmp_path, stop, code):
    """A run whose env hangs, interrupted (Ctrl-C) or terminated: exit code 130 or 143, one
    line and no traceback, no worker left behind."""
    marker = f"OPENRAL_MJX_TEST_MARK={tmp_path.name}"
    env = {**os.environ, "OPENRAL_MJX_TEST_MARK": tmp_path.name}
    argv = [
        sys.executable,
        "-m",
        "openral_mjx.eval",
        "--scene",
        "point_reach",
        "--policy",
        "zero",
        "--n-envs",
        "2",
        "--opt",
        "fault=hang",
        "fault_init_state=0",
        "fault_step=1",
        "--out",
        str(tmp_path / "r.json"),
    ]
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not _workers_of(marker) and time.monotonic() < deadline:
        time.sleep(0.5)
    assert _workers_of(marker), "the workers never started"
    time.sleep(3)  # let it reach the hanging step
    proc.send_signal(stop)
    _, err = proc.communicate(timeout=60)
    said = b"interrupted (SIGINT)" if stop == signal.SIGINT else b"terminated (SIGTERM)"
    assert proc.returncode == code and said in err, err
    assert b"Traceback" not in err, err  # JAX's log of the ended host callback is dropped
    time.sleep(1)
    assert _workers_of(marker) == [] and not (tmp_path / "r.json").exists()


def test_a_simulator_that_cannot_start_is_a_config_error():
    scene = make_scene("point_reach", {"max_steps": 2})
    scene.batch.config = dataclasses.replace(
        scene.batch.config, factory="openral_mjx.host.point_reach:no_such_factory"
    )
    with pytest.raises(ConfigError, match="its workers could not start: AttributeError"):
        evaluate(scene, "zero", n_envs=2)
    assert scene.batch.log_dir.is_dir()  # kept for the user to read
    scene.close()


def test_suite_report_merges_tasks(reach):
    """Two runs merged as a suite: pooled counts, per-task rows, the suite as the task."""
    a = evaluate(reach, "random", n_envs=4, seed=0)
    b = evaluate(reach, "zero", n_envs=4, seed=4)
    merged = merge_reports([a, b], "toy_suite", "random", "cmd")
    assert merged.task == "toy_suite" and merged.n_episodes == 8
    assert merged.successes == a.successes + b.successes
    assert [r.task for r in merged.per_task] == [a.task, b.task]
    assert (merged.ci_low, merged.ci_high) == wilson_interval(merged.successes, 8)
    assert [e.metadata["seed"] for e in merged.episodes] == list(range(8))


def test_host_scenes_are_not_export_cached(reach, tmp_path, monkeypatch):
    """Host callbacks cannot be serialized: the runner keys nothing for the export cache
    (with a policy that has a cache key), writes nothing there, and runs."""
    monkeypatch.setattr(compile_cache, "_EXPORT_DIR", tmp_path)

    def no_key(**parts):
        raise AssertionError(f"keyed for the export cache: {parts.get('program')}")

    monkeypatch.setattr(export_cache, "cache_key", no_key)
    policy = make_policy("random", reach)
    assert policy.cache_key is not None
    runner = EpisodeRunner(reach, policy, n_envs=2, max_steps=STEPS)
    arrays, _ = runner.run(None, np.arange(2))
    ref = _run(reach, np.arange(2), 2)
    np.testing.assert_array_equal(arrays["total_reward"], ref["total_reward"])
    assert list(tmp_path.iterdir()) == []


def test_modules_in_the_workers_directory_are_not_imported(tmp_path, monkeypatch):
    """Workers run in the temp dir; a stray module there (a scratch bisect.py once shadowed
    the standard library's) must not be importable in them."""
    (tmp_path / "stray_module.py").write_text("class Thing:\n    pass\n")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    worker = Worker(sys.executable, None, tmp_path / "worker.log")
    try:
        with pytest.raises(RemoteError, match="No module named 'stray_module'"):
            worker.call({"op": "init", "factory": "stray_module:Thing"}, 60)
        worker.call({"op": "init", "factory": "collections:OrderedDict"}, 60)  # still serves
    finally:
        worker.close()
