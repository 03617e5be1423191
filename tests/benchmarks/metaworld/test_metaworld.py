"""MetaWorld through the host adapter (the `metaworld` worker environment) and its scripted
expert. CI creates that environment first; elsewhere these tests are skipped until
`python -m openral_mjx.host.envs create metaworld` has run."""

import importlib
import json
import os
import signal
import subprocess

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from worker_envs import require_worker_envs

from openral_mjx.cli.eval_text import listing
from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import evaluate
from openral_mjx.evaluation.spec import RunSpec
from openral_mjx.evaluation.suite import evaluate_suite
from openral_mjx.host import envs
from openral_mjx.host.batch import BatchConfig, EnvBatch
from openral_mjx.host.pool import _shim_dir
from openral_mjx.policies import make_policy
from openral_mjx.runner.episode import seed_keys
from openral_mjx.scenes import make_scene, scene_options, scene_suite

# the module (the package's `metaworld` attribute is the scene's constructor)
mw = importlib.import_module("openral_mjx.benchmarks.metaworld.host_scene")

ENV = "metaworld"
require_worker_envs(ENV)
pytestmark = pytest.mark.worker

OBS = {"obs": ((39,), "float32"), "agent_pos": ((4,), "float32")}


@pytest.fixture(scope="module")
def python():
    return envs.ensure_env(ENV)


def test_task_lists_are_metaworlds(python):
    """The scene's task and suite lists (the evaluator cannot import metaworld) are the
    installed MetaWorld's, in its order."""
    script = (
        "import json; from openral_mjx.benchmarks.metaworld.worker_env import suites, task_names; "
        "print(json.dumps({'tasks': task_names(), **suites()}))"
    )
    env = {**os.environ, "PYTHONPATH": _shim_dir()}
    proc = subprocess.run([python, "-c", script], env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    installed = json.loads(proc.stdout.strip().splitlines()[-1])
    assert installed.pop("tasks") == list(mw.TASKS) and len(mw.TASKS) == 50
    assert installed == {k: list(v) for k, v in mw.SUITES.items()}
    assert [len(scene_suite("metaworld", s)) for s in mw.SUITES] == [10, 50, 45, 5]


def _initial(scene, seeds):
    """Reset `seeds` as the runner does (one batched host reset) -> obs and factors."""
    seeds = jnp.asarray(seeds, jnp.int32)
    state = jax.vmap(scene.reset_with_seed)(seeds, seed_keys(seeds)[0])
    return {k: np.asarray(v) for k, v in state.obs.items()}, np.asarray(state.info["factors"])


def test_seed_gives_the_same_initial_state_whatever_ran_before_and_wherever():
    """Seed s -> the same MetaWorld initial state (object and goal positions, hand, the full
    39-D observation) on a repeat after other episodes, with another batch size, in another
    slot of another worker layout; different seeds differ."""
    wide = make_scene("metaworld", {"task": "push-v3", "n_workers": 2}, backend="host")
    narrow = make_scene("metaworld", {"task": "push-v3", "n_workers": 1}, backend="host")
    rng = np.random.default_rng(0)
    try:
        first, factors = _initial(wide, [0, 1, 2, 3])
        wide.batch.step(rng.uniform(-1, 1, (4, 4)), np.zeros(4, bool))
        again, factors_again = _initial(wide, [0, 1, 2, 3])
        late, late_factors = _initial(narrow, [3, 2])  # other slots, one worker, 2 envs
        narrow.batch.step(rng.uniform(-1, 1, (2, 4)), np.zeros(2, bool))
        early, _ = _initial(narrow, [0, 1])
    finally:
        wide.close()
        narrow.close()
    for key in first:
        np.testing.assert_array_equal(again[key], first[key])
        np.testing.assert_array_equal(late[key], first[key][[3, 2]])
        np.testing.assert_array_equal(early[key], first[key][:2])
    np.testing.assert_array_equal(factors_again, factors)
    np.testing.assert_array_equal(late_factors, factors[[3, 2]])
    assert len({tuple(f) for f in factors}) == 4  # four different object/goal placements
    np.testing.assert_array_equal(first["agent_pos"], first["obs"][:, :4])
    np.testing.assert_allclose(first["obs"][:, 36:], factors[:, 3:], rtol=1e-6)  # goal seen


def test_expert_succeeds_in_a_suite_with_per_task_rows_and_factors(monkeypatch):
    """A two-task suite (MetaWorld's own suites run the same way) with the scripted expert,
    which runs in the env workers: every episode succeeds, each task gets its row, and every
    episode carries its object and goal position as factors."""
    monkeypatch.setitem(mw.SUITES, "pair", ("reach-v3", "push-v3"))
    spec = RunSpec(n_envs=4, n_episodes=4, max_steps=150)
    report = evaluate_suite("metaworld", "pair", "metaworld-expert", spec)
    assert [r.task for r in report.per_task] == ["reach-v3", "push-v3"]
    assert all(r.successes == r.n_episodes == 4 for r in report.per_task)
    assert report.backend == "host" and report.success_rate == 1.0
    for e in report.episodes:
        assert e.metadata["error"] is None and e.steps < 150
        assert set(e.metadata["factors"]) == set(mw.FACTORS)
        assert 0.5 < e.metadata["factors"]["goal_y"] < 1.0  # in front of the Sawyer


def test_random_policy_fails_and_the_reports_factors_are_the_resets():
    """The other side of the expert: random actions do not push the puck to the goal. The
    report's factors of seed s are its reset's object and goal positions."""
    scene = make_scene("metaworld", {"task": "push-v3", "n_workers": 1}, backend="host")
    try:
        want = np.concatenate([_initial(scene, [0, 1])[1], _initial(scene, [2, 3])[1]])
        report = evaluate(scene, "random", n_envs=2, n_episodes=4, max_steps=20)
    finally:
        scene.close()
    assert report.successes == 0 and all(e.steps == 20 for e in report.episodes)
    got = [[e.metadata["factors"][k] for k in mw.FACTORS] for e in report.episodes]
    np.testing.assert_array_equal(np.asarray(got, np.float32), want)


def test_config_errors_are_one_line_and_list_the_valid_names(push_c):
    with pytest.raises(ConfigError) as e:
        scene_options("metaworld", {"task": "reach-v2"})
    assert "unknown MetaWorld task 'reach-v2'" in str(e.value) and "push-v3" in str(e.value)
    assert "\n" not in str(e.value)
    with pytest.raises(ConfigError) as e:
        scene_suite("metaworld", "mt25")
    valid = "mt10, mt50, ml45-train, ml45-test"
    assert str(e.value) == f"unknown MetaWorld suite 'mt25'; valid: {valid}"
    with pytest.raises(ConfigError, match="max_steps=501"):
        scene_options("metaworld", {"max_steps": 501})
    with pytest.raises(
        ConfigError, match="runs on --scene metaworld or metaworld_mjx, not 'tabletop_push'"
    ):
        make_policy("metaworld-expert", push_c)
    no_expert = make_scene("metaworld", {"expert": False}, backend="host")
    with pytest.raises(ConfigError, match="drop --opt expert=false"):
        make_policy("metaworld-expert", no_expert)
    assert "metaworld-expert" in listing() and "metaworld" in listing()


def test_a_crashed_worker_fails_only_its_envs(python):
    """Kill one of two workers mid-episode: its two envs fail with the reason, the other
    worker's two go on."""
    config = BatchConfig(
        python, mw.FACTORY, {"task": "reach-v3"}, {**OBS}, 4, n_workers=2, factors=mw.FACTORS
    )
    batch = EnvBatch(config)
    try:
        batch.reset(np.arange(4), [{}] * 4)
        os.kill(batch._workers[0].proc.pid, signal.SIGKILL)
        out = batch.step(np.zeros((4, 4), np.float32), np.zeros(4, bool))
        out = batch.step(np.zeros((4, 4), np.float32), np.zeros(4, bool))
    finally:
        batch.close()
    assert (out["error"][:2] > 0).all() and (out["error"][2:] == 0).all()
    assert "worker 0" in batch.messages[out["error"][0] - 1]


def test_hidden_goal_as_in_metaworlds_ml_benchmarks(python):
    """`goal_observable=false` zeroes the goal in `obs`; the expert still sees it."""
    observation = {**OBS, "expert_action": ((4,), "float32")}
    kwargs = {"task": "reach-v3", "goal_observable": False}
    batch = EnvBatch(BatchConfig(python, mw.FACTORY, kwargs, observation, 4, n_workers=1))
    try:
        out = [batch.reset(np.array([7]), [{}])]
        for _ in range(3):
            out.append(batch.step(out[-1]["obs"]["expert_action"], np.zeros(1, bool)))
    finally:
        batch.close()
    assert all(o["error"][0] == 0 and not o["obs"]["obs"][0, 36:].any() for o in out)
    assert np.abs(out[0]["obs"]["expert_action"]).max() > 0.1  # heading for the hidden goal


def test_camera_observation_is_lerobots(python):
    """With a camera: `pixels` from lerobot's corner2 view, upright RGB, next to the state."""
    observation = {**OBS, "pixels": ((32, 32, 3), "uint8")}
    gl = {"MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}
    kwargs = {"task": "reach-v3", "image_size": 32, "expert": False}
    batch = EnvBatch(BatchConfig(python, mw.FACTORY, kwargs, observation, 4, n_workers=1, env=gl))
    try:
        out = batch.reset(np.array([5]), [{}])
    finally:
        batch.close()
    assert out["error"][0] == 0, batch.messages
    image = out["obs"]["pixels"][0]
    assert image.shape == (32, 32, 3) and image.std() > 10
    # upright: the wooden table (red well above blue) fills the bottom rows, the grey room the top
    warmth = image[..., 0].astype(float) - image[..., 2]
    assert warmth[-8:].mean() > warmth[:8].mean() + 10


@pytest.mark.slow
def test_mt10_expert(tmp_path):
    """MetaWorld's MT10 with its scripted expert, 10 seeds per task (see BENCHMARKS.md for
    all 50 tasks at 200 seeds)."""
    report = evaluate_suite(
        "metaworld", "mt10", "metaworld-expert", RunSpec(n_envs=10, n_episodes=10)
    )
    assert [r.task for r in report.per_task] == list(mw.MT10)
    assert report.success_rate >= 0.9
