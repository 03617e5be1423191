"""ALOHA (gym-aloha) through the host adapter (the `gym-envs` worker environment). CI creates
that environment first; elsewhere these tests are skipped until
`python -m openral_mjx.host.envs create gym-envs` has run. Small camera images keep Mesa's
software renderer fast; lerobot's policies see 480 x 640 (the scene's default)."""

import os
import subprocess

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from worker_envs import require_worker_envs

from openral_mjx.benchmarks.aloha import host_scene as al
from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import evaluate
from openral_mjx.evaluation.spec import RunSpec
from openral_mjx.evaluation.suite import evaluate_suite
from openral_mjx.host import envs
from openral_mjx.host.pool import _shim_dir
from openral_mjx.runner.episode import seed_keys
from openral_mjx.scenes import make_scene, scene_options, scene_suite

ENV = "gym-envs"
require_worker_envs(ENV)
pytestmark = pytest.mark.worker

SMALL = {"image_height": 48, "image_width": 64}
GL = {"MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}


@pytest.fixture(scope="module")
def python():
    return envs.ensure_env(ENV)


def _initial(scene, seeds):
    """Reset `seeds` as the runner does (one batched host reset) -> obs and factors."""
    seeds = jnp.asarray(seeds, jnp.int32)
    state = jax.vmap(scene.reset_with_seed)(seeds, seed_keys(seeds)[0])
    return {k: np.asarray(v) for k, v in state.obs.items()}, np.asarray(state.info["factors"])


def test_seed_gives_the_same_initial_state_whatever_ran_before_and_wherever():
    """Seed s -> the same cube position, arm state and camera image on a repeat after other
    steps and with another batch size and worker layout; different seeds differ."""
    options = {"task": "AlohaTransferCube-v0", **SMALL}
    wide = make_scene("aloha", {**options, "n_workers": 2}, backend="host")
    narrow = make_scene("aloha", {**options, "n_workers": 1}, backend="host")
    low, high = (np.asarray(b) for b in wide.action_bounds())
    rng = np.random.default_rng(0)
    try:
        first, factors = _initial(wide, [0, 1, 2, 3])
        wide.batch.step(rng.uniform(low, high, (4, 14)), np.zeros(4, bool))
        again, factors_again = _initial(wide, [0, 1, 2, 3])
        late, late_factors = _initial(narrow, [3, 2])
    finally:
        wide.close()
        narrow.close()
    assert first["top"].shape == (4, 48, 64, 3) and first["agent_pos"].shape == (4, 14)
    for key in first:
        np.testing.assert_array_equal(again[key], first[key])
        np.testing.assert_array_equal(late[key], first[key][[3, 2]])
    np.testing.assert_array_equal(factors_again, factors)
    np.testing.assert_array_equal(late_factors, factors[[3, 2]])
    assert len({tuple(f) for f in factors}) == 4
    # gym-aloha's cube ranges: x in [0, 0.2], y in [0.4, 0.6]
    assert ((factors[:, 0] >= 0) & (factors[:, 0] <= 0.2)).all()
    assert ((factors[:, 1] >= 0.4) & (factors[:, 1] <= 0.6)).all()
    assert first["top"].std() > 10  # a rendered scene, not a blank frame


def test_random_policy_report_carries_the_resets_factors_and_divergence():
    """Random joint targets on the insertion task through `evaluate` (no camera): every
    episode reports its peg and socket positions, its reset's. Targets jumping over the whole
    joint ranges make gym-aloha's physics blow up (dm_control's PhysicsError) in some episodes:
    those end early as diverged failures, without an error, and the others run on."""
    options = {"image_height": 0, "image_width": 0, "n_workers": 1}
    scene = make_scene("aloha", options, backend="host")
    try:
        (obs, first), (_, second) = _initial(scene, [0, 1]), _initial(scene, [2, 3])
        report = evaluate(scene, "random", n_envs=2, n_episodes=4, max_steps=120)
    finally:
        scene.close()
    want = np.concatenate([first, second])
    assert set(obs) == {"agent_pos"}
    assert report.task == "AlohaInsertion-v0" and report.backend == "host"
    assert report.successes == 0
    assert all(e.metadata["error"] is None for e in report.episodes)
    names = al.FACTORS["AlohaInsertion-v0"]
    got = [[e.metadata["factors"][k] for k in names] for e in report.episodes]
    np.testing.assert_array_equal(np.asarray(got, np.float32), want)
    assert (want[:, 0] > want[:, 2]).all()  # the peg lies right of the socket
    diverged = [e.metadata["diverged"] for e in report.episodes]
    assert report.diverged == sum(diverged) >= 1
    for e in report.episodes:
        assert e.steps < 120 if e.metadata["diverged"] else e.steps == 120


def test_suite_of_both_tasks_with_per_task_rows():
    """`--suite all`: both tasks in turn, a row each, each episode with its task's factors."""
    options = {"image_height": 0, "image_width": 0, "n_workers": 1}
    spec = RunSpec(n_envs=2, max_steps=3)
    report = evaluate_suite("aloha", "all", "random", spec, options=options)
    assert [r.task for r in report.per_task] == list(al.TASKS)
    assert all(r.n_episodes == 2 for r in report.per_task) and report.n_episodes == 4
    names = [set(e.metadata["factors"]) for e in report.episodes]
    assert names == [set(al.FACTORS[t]) for t in al.TASKS for _ in range(2)]


def test_the_top_image_is_gym_alohas(python):
    """The env renders only `top` (gym-aloha's task renders three cameras): the same image
    as gym-aloha's own observation after the same reset, at lerobot's 480 x 640."""
    script = (
        "import numpy as np; from gym_aloha.env import AlohaEnv; "
        "from openral_mjx.benchmarks.aloha.worker_env import make; "
        "a = AlohaEnv(task='transfer_cube', obs_type='pixels_agent_pos'); "
        "b = make(task='AlohaTransferCube-v0'); "
        "ra, _ = a.reset(seed=5); rb, _ = b.reset(seed=5); "
        "assert (ra['pixels']['top'] == rb['top']).all(); "
        "assert (ra['agent_pos'].astype(np.float32) == rb['agent_pos']).all(); "
        "print(rb['top'].shape)"
    )
    env = {**os.environ, **GL, "PYTHONPATH": _shim_dir()}
    proc = subprocess.run([python, "-c", script], env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "(480, 640, 3)"


def test_config_errors_are_one_line_and_list_the_valid_names():
    with pytest.raises(ConfigError) as e:
        scene_options("aloha", {"task": "AlohaPeg-v0"})
    valid = "AlohaInsertion-v0, AlohaTransferCube-v0"
    assert str(e.value) == f"unknown ALOHA task 'AlohaPeg-v0'; valid: {valid}"
    with pytest.raises(ConfigError) as e:
        scene_suite("aloha", "nope")
    assert str(e.value) == "unknown ALOHA suite 'nope'; valid: all"
    assert scene_suite("aloha", "all") == list(al.TASKS)
    with pytest.raises(ConfigError, match="both >= 1, or both 0"):
        scene_options("aloha", {"image_height": 0})
    with pytest.raises(ConfigError, match="gl='glx'"):
        scene_options("aloha", {"gl": "glx"})


@pytest.mark.slow
def test_random_policy_full_episodes_with_lerobots_camera():
    """lerobot's protocol: 400 steps at 480 x 640, 2 seeds per task (random targets may end an
    episode early as diverged, never with an error)."""
    for task in al.TASKS:
        report = evaluate("aloha", "random", n_envs=2, options={"task": task})
        for e in report.episodes:
            assert e.metadata["error"] is None and not e.success
            assert e.steps == 400 or e.metadata["diverged"]
