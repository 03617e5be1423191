"""ManiSkill3 (PickCube, PushCube, StackCube on SAPIEN's CPU PhysX) through the host adapter
(the `maniskill` worker environment). CI creates that environment first; elsewhere these tests
are skipped until `python -m openral_mjx.host.envs create maniskill` has run. A worker's first
reset imports torch and ManiSkill (~10-20 s here), so the fast tests share one worker."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from worker_envs import require_worker_envs

from openral_mjx.benchmarks.maniskill import host_scene as ms
from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import evaluate
from openral_mjx.host import envs
from openral_mjx.host.batch import BatchConfig, EnvBatch
from openral_mjx.host.pool import Worker
from openral_mjx.runner.episode import seed_keys
from openral_mjx.scenes import make_scene, scene_options

ENV = "maniskill"
require_worker_envs(ENV)
pytestmark = pytest.mark.worker


@pytest.fixture(scope="module")
def python():
    return envs.ensure_env(ENV)


@pytest.fixture(scope="module")
def stack():
    """StackCube-v1 in one worker, shared by the fast tests."""
    scene = make_scene("maniskill", {"task": "StackCube-v1", "n_workers": 1}, backend="host")
    yield scene
    scene.close()


def _initial(scene, seeds):
    """Reset `seeds` as the runner does (one batched host reset) -> obs and factors."""
    seeds = jnp.asarray(seeds, jnp.int32)
    state = jax.vmap(scene.reset_with_seed)(seeds, seed_keys(seeds)[0])
    return {k: np.asarray(v) for k, v in state.obs.items()}, np.asarray(state.info["factors"])


def test_seed_gives_the_same_initial_state_whatever_ran_before(stack):
    """Seed s -> the same state vector and cube placements on a repeat after random steps
    and in the other slot; seeds differ; the factors are the cubes' positions. (Two slots
    throughout, as `evaluate` below: another slot count would restart the worker.)"""
    first, factors = _initial(stack, [0, 1])
    rng = np.random.default_rng(0)
    for _ in range(3):
        stack.batch.step(rng.uniform(-1, 1, (2, 8)), np.zeros(2, bool))
    again, factors_again = _initial(stack, [0, 1])
    swapped, swapped_factors = _initial(stack, [1, 0])
    assert first["state"].shape == (2, 48) and first["state"].dtype == np.float32
    np.testing.assert_array_equal(again["state"], first["state"])
    np.testing.assert_array_equal(swapped["state"], first["state"][[1, 0]])
    np.testing.assert_array_equal(factors_again, factors)
    np.testing.assert_array_equal(swapped_factors, factors[[1, 0]])
    assert not np.array_equal(factors[0], factors[1])  # two different placements
    # ManiSkill places both cubes within 0.1 + 0.2 m of the table's centre, apart
    assert (np.abs(factors) <= 0.3 + 1e-6).all()
    a, b = factors[:, :2], factors[:, 2:]
    assert (np.linalg.norm(a - b, axis=1) > 0.04).all()


def test_random_policy_report_carries_the_resets_factors(stack):
    """Random actions through `evaluate`: every episode runs its steps without error and
    reports the factors of its reset."""
    (_, first), (_, second) = _initial(stack, [0, 1]), _initial(stack, [2, 3])
    report = evaluate(stack, "random", n_envs=2, n_episodes=4, max_steps=5)
    assert report.backend == "host" and report.task == "StackCube-v1" and report.n_episodes == 4
    assert all(e.metadata["error"] is None and e.steps == 5 for e in report.episodes)
    got = [[e.metadata["factors"][k] for k in ms.FACTORS["StackCube-v1"]] for e in report.episodes]
    np.testing.assert_array_equal(np.asarray(got, np.float32), np.concatenate([first, second]))
    assert report.success_rate == 0  # random arm motions in 5 steps stack nothing


def test_scene_layout_without_starting_workers():
    """Sizes, bounds, rates and factor names per task and controller; no worker starts."""
    for task, size in ms.STATE_SIZE.items():
        for mode, n_action in ms.CONTROL_MODES.items():
            scene = make_scene("maniskill", {"task": task, "control_mode": mode}, backend="host")
            try:
                assert scene.host_spec.batch.observation == {"state": ((size,), "float32")}
                assert scene.action_size == n_action and scene.robot_name == "panda"
                low, high = scene.action_bounds()
                assert (np.asarray(low) == -1).all() and (np.asarray(high) == 1).all()
                assert scene.max_steps == 50 and scene.backend.control_dt == 0.05
                assert scene.host_spec.batch.factors == ms.FACTORS[task]
                assert scene.batch.n == 0  # nothing started
            finally:
                scene.close()


def test_config_errors_are_one_line_and_list_the_valid_names():
    with pytest.raises(ConfigError) as e:
        scene_options("maniskill", {"task": "PegInsertionSide-v1"})
    assert str(e.value) == (
        "unknown ManiSkill task 'PegInsertionSide-v1'; valid: PickCube-v1, PushCube-v1, "
        "StackCube-v1"
    )
    with pytest.raises(ConfigError) as e:
        scene_options("maniskill", {"control_mode": "pd_joint_pos"})
    valid = "pd_joint_delta_pos, pd_ee_delta_pos, pd_ee_delta_pose"
    assert str(e.value) == f"unknown ManiSkill control_mode 'pd_joint_pos'; valid: {valid}"
    with pytest.raises(ConfigError, match="max_steps=0"):
        scene_options("maniskill", {"max_steps": 0})
    with pytest.raises(ConfigError, match="requires robot 'panda', not 'so101'"):
        scene_options("maniskill", {"robot": "so101"})
    with pytest.raises(ConfigError, match="runs on backend host"):
        make_scene("maniskill", backend="c")


def _push(state: np.ndarray, phase: list[int]) -> np.ndarray:
    """A scripted PushCube policy on the state vector (``pd_ee_delta_pos``): lower the closed
    gripper behind the cube, then push it along +x into the goal region."""
    tcp, cube = state[18:21], state[28:31]  # qpos 9, qvel 9, tcp_pose 7, goal 3, obj_pose 7
    behind = cube + np.array([-0.05, 0.0, 0.0])
    if phase[0] == 0 and np.linalg.norm(tcp - behind) < 0.01:
        phase[0] = 1
    if phase[0] == 0:  # above the point behind the cube, then down to it
        above = np.linalg.norm((tcp - behind)[:2]) > 0.01
        target = behind + np.array([0.0, 0.0, 0.06 if above else 0.0])
    else:
        target = np.array([cube[0] + 0.1, cube[1], behind[2]])
    delta = np.clip((target - tcp) / 0.1, -1, 1)  # the controller's 0.1 m per unit step
    return np.concatenate([delta, [-1.0]]).astype(np.float32)  # gripper closed


@pytest.mark.slow
def test_batch_matches_the_env_stepped_directly_and_a_scripted_push_succeeds(python, tmp_path):
    """Two PushCube envs in one worker against each env alone in a worker: the same state
    after the reset and every step of a scripted push, which succeeds for both seeds (a
    finished env is not stepped again by the batch)."""
    kwargs = {"task": "PushCube-v1", "control_mode": "pd_ee_delta_pos", "fresh": True}
    obs = {"state": ((35,), "float32")}
    batch = EnvBatch(BatchConfig(python, ms.FACTORY, kwargs, obs, 4, n_workers=1))
    phases = [[0], [0]]
    try:
        trace = [batch.reset(np.array([21, 22]), [{}, {}])]
        actions = []
        for _ in range(ms.MAX_STEPS):
            state = trace[-1]["obs"]["state"]
            actions.append(np.stack([_push(state[i], phases[i]) for i in range(2)]))
            trace.append(batch.step(actions[-1], np.zeros(2, bool)))
            if trace[-1]["success"].all():
                break
    finally:
        batch.close()
    assert all((t["error"] == 0).all() for t in trace)
    assert trace[-1]["success"].all()
    worker = Worker(python, {}, tmp_path / "direct.log", name="direct")
    try:
        worker.call({"op": "init", "factory": ms.FACTORY, "kwargs": kwargs}, 300)
        for i, seed in enumerate((21, 22)):
            end = next(t for t, out in enumerate(trace) if out["success"][i])  # then frozen
            reset = {"seed": seed, "options": {}}
            want = [worker.call({"op": "call", "method": "reset", "kwargs": reset}, 120)[0]]
            for a in actions[:end]:
                step = {"op": "call", "method": "step", "kwargs": {"action": a[i]}}
                want.append(worker.call(step, 60)[0])
            for t, w in enumerate(want):
                np.testing.assert_array_equal(trace[t]["obs"]["state"][i], w["state"], str(t))
    finally:
        worker.close()


@pytest.mark.slow
@pytest.mark.parametrize("task", ms.TASKS)
def test_random_policy_full_episodes(task):
    """ManiSkill's episode length (50 steps), 4 seeds, two workers, each task."""
    report = evaluate("maniskill", "random", n_envs=4, n_episodes=4, options={"task": task})
    assert all(e.metadata["error"] is None for e in report.episodes)
    assert all(e.steps == 50 or e.success for e in report.episodes)
